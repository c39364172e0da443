"""A robot's inbox on a relay (bridge_server/zenoh/inbox.py), on a real event loop with its
callbacks called from another thread, as Zenoh calls them, while the loop is held busy:

- past the bound, topic messages lose their oldest, reliable data its newest, each counted,
  logged once, and for reliable data the robot's clients told how many were lost;
- two robots with items waiting are handled in turns of ``BATCH``, not one after the other;
- a graph document over the size limit never waits; a newer one replaces the waiting one.
"""

from __future__ import annotations

import asyncio
import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import pytest

from bridge_server.zenoh import inbox
from bridge_server.zenoh.inbox import BATCH, GRAPH_BYTES, RELIABLE_LIMIT, SAMPLE_LIMIT, Inbox

pytestmark = pytest.mark.timeout(30)


@dataclass
class Item:
    """What Zenoh hands a callback, as far as the inbox looks at it (its payload)."""

    n: int
    payload: bytes = b""


def _from_zenohs_thread(calls: Callable[[], Any]) -> None:
    """Run ``calls`` on another thread while the loop waits here (held busy, as by a long
    handler): what they queue is handled once this returns."""
    thread = threading.Thread(target=calls)
    thread.start()
    thread.join()


async def _settled(box: Inbox) -> None:
    """Until nothing waits in ``box`` (each turn of the loop takes a batch), and a turn
    more (for what was handed to the loop otherwise)."""
    await asyncio.sleep(0)
    while any(box.waiting().values()) or box._scheduled:
        await asyncio.sleep(0)
    await asyncio.sleep(0)


async def test_past_the_bound_messages_lose_the_oldest_and_replies_are_told(
        caplog: pytest.LogCaptureFixture) -> None:
    """2000 messages and 5000 replies put while the loop is busy: the newest 1024 messages
    and the first 4096 replies are handled, in order; the rest counted, one log line per
    kind naming the robot, and the robot's clients told that 904 replies were lost."""
    caplog.set_level(logging.WARNING)
    box = Inbox(asyncio.get_running_loop(), "robot9")
    messages: list[int] = []
    replies: list[int] = []
    told: list[str] = []
    box.told.append(told.append)
    sample = box.sample(lambda item: messages.append(item.n))
    reliable = box.reliable(lambda item: replies.append(item.n))

    def flood() -> None:
        for n in range(2000):
            sample(Item(n))
        for n in range(5000):
            reliable(Item(n))

    _from_zenohs_thread(flood)
    await _settled(box)
    assert messages == list(range(2000 - SAMPLE_LIMIT, 2000))
    assert replies == list(range(RELIABLE_LIMIT))
    assert box.faults.counts == {"messages_dropped": 2000 - SAMPLE_LIMIT,
                                 "replies_dropped": 5000 - RELIABLE_LIMIT}
    assert told == [f"robot robot9: {5000 - RELIABLE_LIMIT} replies or requests from it were "
                    "dropped (it sends more than this relay handles); a call or goal may fail "
                    "for it"]
    lines = [r.getMessage() for r in caplog.records if r.name.startswith("bridge_server")]
    assert len(lines) <= 4 and all("robot robot9" in line for line in lines), lines


async def test_two_robots_waiting_are_handled_in_turns() -> None:
    """300 messages of robot A then 300 of robot B put while the loop is busy: the loop
    handles them in turns of BATCH (A, B, A, B...), B's first before A's last."""
    loop = asyncio.get_running_loop()
    order: list[str] = []
    boxes = {name: Inbox(loop, name) for name in "AB"}
    def handler(name: str) -> Callable[[Any], None]:
        return lambda _: order.append(name)

    cross = {name: box.sample(handler(name)) for name, box in boxes.items()}
    _from_zenohs_thread(lambda: [cross[name](Item(n)) for name in "AB" for n in range(300)])
    for box in boxes.values():
        await _settled(box)
    assert len(order) == 600
    assert order[:2 * BATCH] == ["A"] * BATCH + ["B"] * BATCH, order[:2 * BATCH]
    assert order.index("B") < len(order) - 1 - order[::-1].index("A")


async def test_graph_documents_over_the_limit_never_wait_and_the_newest_replaces(
        caplog: pytest.LogCaptureFixture) -> None:
    """Three graph documents while the loop is busy, one over GRAPH_BYTES: that one is
    dropped and counted, the other two replaced each other: only the newest is handled."""
    box = Inbox(asyncio.get_running_loop(), "robot9")
    got: list[Any] = []
    graph = box.graph(got.append)
    big = Item(0, b"x" * (GRAPH_BYTES + 1))
    _from_zenohs_thread(lambda: [graph(Item(1)), graph(big), graph(Item(2))])
    await _settled(box)
    assert got == [Item(2)]
    assert box.faults.counts == {"graph_too_large": 1, "graph_superseded": 1}
    assert f"a graph document of {GRAPH_BYTES + 1} bytes" in box.faults.last["graph_too_large"]


def test_a_count_is_logged_once_then_at_each_hundredfold() -> None:
    """1, 100 and 10000 are where a kind's count is logged again."""
    assert [n for n in range(1, 20001) if inbox._hundreds(n) > inbox._hundreds(n - 1)] == [
        100, 10000]


async def test_a_querys_end_comes_after_its_replies() -> None:
    """300 replies of a query and then its end, while the loop is busy: the end is handled
    after every reply (a goal's result is not taken for a robot that did not answer)."""
    box = Inbox(asyncio.get_running_loop(), "robot9")
    seen: list[Any] = []
    reply = box.reliable(lambda item: seen.append(item.n))
    end = box.end(lambda: seen.append("end"))
    _from_zenohs_thread(lambda: [*(reply(Item(n)) for n in range(300)), end()])
    await _settled(box)
    assert seen == [*range(300), "end"]
