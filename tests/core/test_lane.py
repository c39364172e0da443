"""The ordered off-loop lane (rosbridge_core/codec/lane.py) on its own: order, one item at a
time, its two bounds and two ways of keeping them, a failing handler, closing, the worker
thread. The Foxglove channel's and the relay topic's use of it are tested with them
(tests/peers/test_foxglove_budget.py, tests/relay/test_message_budget.py)."""

from __future__ import annotations

import asyncio
import logging
import threading

import pytest

from rosbridge_core.codec.lane import LaneFull, OrderedLane, off_loop


class Recorder:
    """A lane handler that records what it handles and waits, per item, until let go."""

    def __init__(self) -> None:
        self.started: list[str] = []
        self.finished: list[str] = []
        self.gates: dict[str, asyncio.Event] = {}
        self.change = asyncio.Event()

    def gate(self, item: str) -> asyncio.Event:
        """The event that lets ``item``'s handling finish."""
        return self.gates.setdefault(item, asyncio.Event())

    async def __call__(self, item: str) -> None:
        self.started.append(item)
        self.change.set()
        await self.gate(item).wait()
        self.finished.append(item)
        self.change.set()

    async def until(self, check: object) -> None:
        """Wait until ``check()`` holds (it is looked at on each change)."""
        assert callable(check)
        while not check():
            self.change.clear()
            await asyncio.wait_for(self.change.wait(), 5)


async def test_items_are_handled_in_order_one_at_a_time() -> None:
    """Each item is handled after the one pushed before it has finished, in push order, and
    the lane is busy from the first push until the last has been handled."""
    handler = Recorder()
    lane: OrderedLane[str] = OrderedLane(handler, max_waiting=10)
    assert not lane.busy
    for item in ("a", "b", "c"):
        lane.push(item)
    assert lane.busy
    await handler.until(lambda: handler.started == ["a"])
    handler.gate("c").set()  # c may finish at once, but only after a and b
    handler.gate("b").set()
    await asyncio.sleep(0)
    assert handler.started == ["a"]
    handler.gate("a").set()
    await handler.until(lambda: handler.finished == ["a", "b", "c"])
    await handler.until(lambda: not lane.busy)
    assert not lane.busy


async def test_a_full_lane_refuses_the_newest() -> None:
    """Without drop_oldest, a push while max_waiting items wait raises LaneFull naming how
    many wait and the bound; the refused item is never handled, the others all are."""
    handler = Recorder()
    lane: OrderedLane[str] = OrderedLane(handler, max_waiting=2)
    lane.push("first")
    await handler.until(lambda: handler.started == ["first"])  # taken: no longer waiting
    lane.push("w1")
    lane.push("w2")
    with pytest.raises(LaneFull, match=r"^2 wait \(at most 2\)$"):
        lane.push("refused")
    for item in ("first", "w1", "w2"):
        handler.gate(item).set()
    await handler.until(lambda: not lane.busy)
    assert handler.finished == ["first", "w1", "w2"]


async def test_a_lane_that_drops_the_oldest_keeps_both_bounds() -> None:
    """With drop_oldest, a push past max_waiting or past max_bytes drops the oldest waiting
    items until the new one fits, says how many, and keeps the order of the rest."""
    handler = Recorder()
    lane: OrderedLane[str] = OrderedLane(handler, max_waiting=3, max_bytes=10, size=len,
                                         drop_oldest=True)
    lane.push("busy")
    await handler.until(lambda: handler.started == ["busy"])
    assert [lane.push(item) for item in ("aa", "bb", "cc")] == [0, 0, 0]
    assert lane.push("dd") == 1  # the count: aa goes
    assert list(lane.waiting) == ["bb", "cc", "dd"] and lane.bytes == 6
    assert lane.push("eeeeeeee") == 2  # the bytes: 6 + 8 > 10, 4 + 8 > 10, 2 + 8 fits
    assert list(lane.waiting) == ["dd", "eeeeeeee"] and lane.bytes == 10
    for item in ("busy", "dd", "eeeeeeee"):
        handler.gate(item).set()
    await handler.until(lambda: not lane.busy)
    assert handler.finished == ["busy", "dd", "eeeeeeee"] and lane.bytes == 0


async def test_a_failing_handler_is_logged_and_the_lane_goes_on(
        caplog: pytest.LogCaptureFixture) -> None:
    """An exception the handler lets out is logged with its traceback; the next item is
    handled."""
    handled: list[int] = []
    done = asyncio.Event()

    async def handle(item: int) -> None:
        if item == 1:
            raise ValueError("bad item")
        handled.append(item)
        done.set()

    lane: OrderedLane[int] = OrderedLane(handle, max_waiting=4)
    with caplog.at_level(logging.ERROR, logger="rosbridge_core.codec.lane"):
        lane.push(1)
        lane.push(2)
        await asyncio.wait_for(done.wait(), 5)
    assert handled == [2]
    assert "handler failed" in caplog.text and "ValueError: bad item" in caplog.text


async def test_closing_drops_what_waits_and_stops_the_handling() -> None:
    """close() drops the waiting items, cancels the one being handled and leaves the lane
    idle; a later push starts it again."""
    handler = Recorder()
    lane: OrderedLane[str] = OrderedLane(handler, max_waiting=4)
    lane.push("a")
    lane.push("b")
    await handler.until(lambda: handler.started == ["a"])
    lane.close()
    assert not lane.busy and not lane.waiting and lane.bytes == 0
    handler.gate("a").set()
    handler.gate("c").set()
    lane.push("c")
    await handler.until(lambda: handler.finished == ["c"])
    assert handler.started == ["a", "c"]


async def test_off_loop_runs_the_work_on_a_worker_thread() -> None:
    """off_loop runs the work on another thread than the loop's and gives back its result,
    or raises what it raised."""
    result = await off_loop(lambda n: (n * 2, threading.current_thread()), 21)
    assert result[0] == 42 and result[1] is not threading.current_thread()

    def fail(_: int) -> int:
        raise KeyError("no")

    with pytest.raises(KeyError):
        await off_loop(fail, 0)
