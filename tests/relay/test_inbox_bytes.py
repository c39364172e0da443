"""A robot's inbox on a relay holds its queues to their byte bounds as well as their counts,
and counts, logs and tells what it drops (issue 54: the byte bounds were untested;
``bytes + size > limit`` turned into ``-`` or ``>=``, or ``_Lane.pop`` adding instead of
taking off, went unnoticed, and so did the faults' texts and several edges).

The bounds are made small here (a few payloads) so that an exact edge can be tested: a
queue holds payloads up to its byte bound exactly, never one byte more.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from types import SimpleNamespace
from typing import Any

import pytest
import zenoh

from bridge_server.zenoh import inbox
from bridge_server.zenoh.inbox import GRAPH_BYTES, RELIABLE_LIMIT, SAMPLE_LIMIT, Faults, Inbox
from tests.relay.test_inbox import Item, _from_zenohs_thread

pytestmark = pytest.mark.timeout(30)

PAYLOAD = 300
"""Bytes of each payload put."""
HELD = 3
"""Payloads a queue holds at once: its byte bound is HELD payloads exactly."""


@pytest.fixture
def box(monkeypatch: pytest.MonkeyPatch) -> Callable[[], Inbox]:
    """Makes inboxes whose queues hold HELD payloads by bytes (their counts are no bound)."""
    monkeypatch.setattr(inbox, "SAMPLE_BYTES", HELD * PAYLOAD)
    monkeypatch.setattr(inbox, "RELIABLE_BYTES", HELD * PAYLOAD)

    def make() -> Inbox:
        return Inbox(asyncio.get_running_loop(), "robot9")

    return make


async def _settled(box: Inbox) -> None:
    """Until no item waits in ``box`` and no drain is due, and a turn more; by the items
    waiting, not their bytes (a byte count gone wrong fails an assertion, not this wait)."""
    for _ in range(10_000):
        await asyncio.sleep(0)
        waiting = box.waiting()
        if not (waiting["messages"] or waiting["reliable"] or box._scheduled):
            await asyncio.sleep(0)
            return
    raise AssertionError(f"robot9's inbox never drained: {box.waiting()}")


def _items(n: int, size: int = PAYLOAD) -> list[Item]:
    return [Item(i, bytes(size)) for i in range(n)]


async def test_topic_messages_are_held_to_the_byte_bound_exactly(box: Callable[[], Inbox]
                                                                 ) -> None:
    """Ten payloads while the loop is busy: the newest HELD wait (HELD payloads are the
    bound exactly: none of them is dropped for reaching it), their bytes shown as waiting;
    the others are dropped oldest first and counted."""
    got: list[int] = []
    one = box()
    sample = one.sample(lambda item: got.append(item.n))
    waiting: list[dict[str, int]] = []

    def flood() -> None:
        for item in _items(10):
            sample(item)
        waiting.append(one.waiting())

    _from_zenohs_thread(flood)
    assert waiting == [{"messages": HELD, "message_bytes": HELD * PAYLOAD, "reliable": 0}]
    await _settled(one)
    assert got == list(range(10 - HELD, 10))
    assert one.faults.counts == {"messages_dropped": 10 - HELD}
    assert one.waiting() == {"messages": 0, "message_bytes": 0, "reliable": 0}


async def test_a_message_one_byte_over_the_bound_drops_the_oldest(box: Callable[[], Inbox]
                                                                  ) -> None:
    """HELD - 1 payloads and then one a byte longer than a payload: they pass the bound by
    one byte together, so the oldest is dropped."""
    got: list[int] = []
    one = box()
    sample = one.sample(lambda item: got.append(item.n))
    _from_zenohs_thread(lambda: [sample(item) for item in
                                 [*_items(HELD - 1), Item(HELD - 1, bytes(PAYLOAD + 1))]])
    await _settled(one)
    assert got == list(range(1, HELD))
    assert one.faults.counts == {"messages_dropped": 1}


async def test_a_queue_drained_takes_a_full_bound_again(box: Callable[[], Inbox]) -> None:
    """Bytes handled are taken off the queue's count: after three rounds of HELD payloads,
    each handled before the next, every payload was handled and none dropped."""
    got: list[int] = []
    one = box()
    sample = one.sample(lambda item: got.append(item.n))
    reply = one.reliable(lambda item: got.append(item.n))
    for _ in range(3):
        _from_zenohs_thread(lambda: [*(sample(i) for i in _items(HELD)),
                                     *(reply(i) for i in _items(HELD))])
        await _settled(one)
    assert got == [*range(HELD), *range(HELD)] * 3
    assert one.faults.counts == {}


async def test_replies_are_held_to_the_byte_bound_and_the_rest_told(box: Callable[[], Inbox]
                                                                    ) -> None:
    """Ten reply payloads while the loop is busy: the first HELD are handled in order (the
    bound exactly), the other seven dropped, counted and told to the robot's clients."""
    got: list[int] = []
    told: list[str] = []
    one = box()
    one.told.append(told.append)
    reply = one.reliable(lambda item: got.append(item.n))
    _from_zenohs_thread(lambda: [reply(item) for item in _items(10)])
    await _settled(one)
    assert got == list(range(HELD))
    assert one.faults.counts == {"replies_dropped": 10 - HELD}
    assert told and told[0].startswith(f"robot robot9: {10 - HELD} replies or requests")


async def test_a_querys_end_passes_a_full_reliable_queue(box: Callable[[], Inbox]) -> None:
    """A query's end put when its replies filled the reliable queue's bytes is not dropped,
    and counts no bytes: the reply after it is still dropped only for the bound."""
    got: list[Any] = []
    one = box()
    reply = one.reliable(lambda item: got.append(item.n))
    end = one.end(lambda: got.append("end"))
    _from_zenohs_thread(lambda: [*(reply(i) for i in _items(HELD)), end(),
                                 reply(Item(9, b""))])
    await _settled(one)
    assert got == [*range(HELD), "end", 9]
    assert one.faults.counts == {}


@pytest.mark.parametrize(("arg", "size"), [
    (Item(0, b"abc"), 3),
    (SimpleNamespace(payload=zenoh.ZBytes(b"abcd")), 4),
    (SimpleNamespace(ok=SimpleNamespace(payload=b"abcde")), 5),
    (SimpleNamespace(ok=None, err=SimpleNamespace(payload=b"why")), 0),
    (SimpleNamespace(ok=SimpleNamespace()), 0),
    (SimpleNamespace(), 0),
], ids=["sample", "zbytes", "reply", "error_reply", "reply_without_payload", "nothing"])
def test_what_an_item_counts_against_the_bytes(arg: Any, size: int) -> None:
    """A sample counts its payload, a reply its ok payload, and what has none counts 0."""
    assert inbox._size(arg) == size


# -- what is dropped, counted, logged and told ------------------------------------------------

def _box(max_message: int = 1000) -> Inbox:
    return Inbox(asyncio.get_running_loop(), "robot9", max_message=max_message)


def _reply(size: int, key: str | None = "robot9/@reply/1") -> Any:
    ok = SimpleNamespace(payload=bytes(size), **({"key_expr": key} if key else {}))
    return SimpleNamespace(ok=ok)


def test_a_fault_is_logged_first_with_its_cause_then_at_each_hundredfold(
        caplog: pytest.LogCaptureFixture) -> None:
    """The first fault of a kind is logged naming the robot, what happened, the kind and the
    count, with the exception that caused it; the next ones are not, until the hundredth
    (logged without the exception again)."""
    caplog.set_level(logging.WARNING, "bridge_server")
    faults = Faults("robot9")
    cause = ValueError("bad bytes")
    for _ in range(100):
        faults.add("handling_failed", "handling what it sent failed (ValueError)", exc=cause)
    assert faults.counts == {"handling_failed": 100}
    first, hundredth = caplog.records
    assert first.getMessage() == ("robot robot9: handling what it sent failed (ValueError) "
                                  "(handling_failed: 1 so far; counted on the relay's page, "
                                  "not logged each time)")
    assert first.exc_info is not None and first.exc_info[1] is cause
    assert "(handling_failed: 100 so far;" in hundredth.getMessage()
    assert not hundredth.exc_info


async def test_one_message_may_push_out_several_old_ones(monkeypatch: pytest.MonkeyPatch
                                                         ) -> None:
    """Three small messages waiting, then one nearly as large as the byte bound: all three
    are dropped for it, counted as three, with the text naming the count bound."""
    monkeypatch.setattr(inbox, "SAMPLE_BYTES", 900)
    got: list[int] = []
    box = _box()
    sample = box.sample(lambda item: got.append(item.n))
    _from_zenohs_thread(lambda: [*(sample(Item(n, bytes(100))) for n in range(3)),
                                 sample(Item(3, bytes(850)))])
    await _settled(box)
    assert got == [3]
    assert box.faults.counts == {"messages_dropped": 3}
    assert box.faults.last["messages_dropped"] == (
        "topic messages dropped, the oldest first: it sends faster than this relay handles "
        f"(at most {SAMPLE_LIMIT} wait)")


async def test_replies_over_the_message_bound_are_told_as_lost() -> None:
    """Two replies over the per-message bound, and nothing else: both are counted as too
    large (naming the reply's key, or "(a reply)" when it has none) and the robot's clients
    are told two were lost. A reply exactly at the bound is handled."""
    told: list[str] = []
    got: list[int] = []
    box = _box(max_message=1000)
    box.told.append(told.append)
    reply = box.reliable(lambda r: got.append(len(r.ok.payload)))
    _from_zenohs_thread(lambda: [reply(_reply(1001)), reply(_reply(5000, key=None))])
    await _settled(box)
    assert told == ["robot robot9: 2 replies or requests from it were dropped (it sends more "
                    "than this relay handles); a call or goal may fail for it"]
    assert box.faults.counts == {"message_too_large": 2}
    assert box.faults.last["message_too_large"] == (
        "a message of 5000 bytes on (a reply), over the limit of 1000 bytes a message "
        "(--max-robot-message-bytes), dropped")
    _from_zenohs_thread(lambda: reply(_reply(1001)))
    assert box.faults.last["message_too_large"].startswith(
        "a message of 1001 bytes on robot9/@reply/1, over")
    _from_zenohs_thread(lambda: reply(_reply(1000)))
    await _settled(box)
    assert got == [1000]


async def test_a_reply_over_the_count_bound_says_what_happened() -> None:
    """A reply past RELIABLE_LIMIT waiting is dropped with a text naming the bound."""
    box = _box()
    reply = box.reliable(lambda r: None)
    _from_zenohs_thread(lambda: [reply(Item(n)) for n in range(RELIABLE_LIMIT + 1)])
    await _settled(box)
    assert box.faults.last["replies_dropped"] == (
        "replies or requests dropped: it sends more than this relay handles "
        f"(at most {RELIABLE_LIMIT} wait)")


async def test_a_graph_document_at_the_bound_is_read_and_one_alone_replaces_nothing(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A graph document of exactly GRAPH_BYTES is handled; one document alone counts no
    replacement; a second before the first is read does, saying so."""
    got: list[int] = []
    box = _box(max_message=2 * GRAPH_BYTES)
    graph = box.graph(lambda item: got.append(item.n))
    _from_zenohs_thread(lambda: graph(Item(1, bytes(GRAPH_BYTES))))
    await _settled(box)
    assert got == [1] and box.faults.counts == {}
    _from_zenohs_thread(lambda: [graph(Item(2)), graph(Item(3))])
    await _settled(box)
    assert got == [1, 3]
    assert box.faults.last == {"graph_superseded": "graph documents replaced by a newer one "
                                                   "before this relay read them"}


async def test_a_querys_end_alone_is_handled_and_takes_no_room(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A query's end with nothing before it is handled (it wakes the loop itself); once
    handled, the reliable queue holds its byte bound exactly again: the end took none of it."""
    monkeypatch.setattr(inbox, "RELIABLE_BYTES", 900)
    seen: list[Any] = []
    box = _box()
    end = box.end(lambda: seen.append("end"))
    reply = box.reliable(lambda item: seen.append(item.n))
    _from_zenohs_thread(end)
    await _settled(box)
    assert seen == ["end"]
    _from_zenohs_thread(lambda: [reply(Item(n, bytes(300))) for n in range(3)] + [
        reply(Item(3, b"x"))])
    await _settled(box)
    assert seen == ["end", 0, 1, 2] and box.faults.counts == {"replies_dropped": 1}


def test_the_message_bound_is_one_byte_or_more() -> None:
    """--max-robot-message-bytes 1 is taken; 0 is refused naming the option."""
    loop = asyncio.new_event_loop()
    try:
        inbox.set_message_bytes(1)
        assert Inbox(loop, "r").max_message == 1
        with pytest.raises(ValueError, match=r"^--max-robot-message-bytes 0: expected 1 or more$"):
            inbox.set_message_bytes(0)
    finally:
        inbox.set_message_bytes(inbox.MESSAGE_BYTES)
        loop.close()


def test_what_arrives_after_the_loop_closed_is_no_error() -> None:
    """A Zenoh callback after the relay's loop closed (at shutdown) raises nothing."""
    loop = asyncio.new_event_loop()
    box = Inbox(loop, "robot9")
    crossings: list[Callable[[Any], None]] = [box.sample(print), box.reliable(print)]
    loop.close()
    for cross in crossings:
        cross(Item(0, b"late"))
    box.end(lambda: None)()
