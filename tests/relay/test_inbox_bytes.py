"""A robot's inbox on a relay holds its queues to their byte bounds as well as their counts
(issue 54: the byte bounds were untested; ``bytes + size > limit`` turned into ``-`` or
``>=``, or ``_Lane.pop`` adding instead of taking off, went unnoticed).

The bounds are made small here (a few payloads) so that an exact edge can be tested: a
queue holds payloads up to its byte bound exactly, never one byte more.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from types import SimpleNamespace
from typing import Any

import pytest
import zenoh

from bridge_server.zenoh import inbox
from bridge_server.zenoh.inbox import Inbox
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
