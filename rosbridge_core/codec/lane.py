"""One stream's items handled in order, each awaited before the next, the costly work of
one done off the event loop: a bounded lane.

A large message is decoded on a worker thread (:func:`off_loop`, on
:func:`~rosbridge_core.codec.budget.workers`) so that the event loop keeps serving everyone
else; the messages of the same stream after it must not overtake it, so they wait in its
:class:`OrderedLane`, and the lane holds at most ``max_waiting`` of them (and
``max_bytes``): past that it refuses the newest (:class:`LaneFull`) or drops the oldest,
as its owner chose. An item that comes while the lane is idle is not the lane's: its owner
handles it at once, unless it is itself costly (:attr:`OrderedLane.busy` says which).

Two owners: a Foxglove client's channel (:mod:`bridge_server.foxglove.inbound`: a client's
``cdr`` messages on their way to ROS, the newest refused past four) and a relay's topic
(:mod:`bridge_server.zenoh.decode`: a robot's messages on their way to the viewers, the
oldest dropped past 64 or 64 MiB).
"""

from __future__ import annotations

import asyncio
import logging
from collections import deque
from collections.abc import Awaitable, Callable
from typing import Generic, TypeVar

from rosbridge_core.codec.budget import workers

__all__ = ["LaneFull", "OrderedLane", "off_loop"]

log = logging.getLogger(__name__)

T = TypeVar("T")
R = TypeVar("R")


class LaneFull(Exception):
    """A lane that refuses the newest holds as many items as it may: this one was not
    queued (the text says how many wait, and the bound)."""


async def off_loop(work: Callable[[T], R], item: T) -> R:
    """``work(item)`` on one of the shared decode workers; its result (or what it raised)."""
    return await asyncio.get_running_loop().run_in_executor(workers(), work, item)


class OrderedLane(Generic[T]):
    """One stream's items handed to ``handle`` in the order they were pushed, each awaited
    before the next (see the module text).

    ``max_waiting`` items wait at most, and their ``size`` at most ``max_bytes`` (none by
    default); a push past a bound raises :class:`LaneFull` (``drop_oldest`` False) or drops
    the oldest waiting until it fits (``drop_oldest`` True). An exception ``handle`` lets
    out is logged and the lane goes on with the next item.
    """

    def __init__(self, handle: Callable[[T], Awaitable[None]], *, max_waiting: int,
                 max_bytes: int | None = None, size: Callable[[T], int] = lambda item: 0,
                 drop_oldest: bool = False) -> None:
        self.handle = handle
        self.max_waiting = max_waiting
        self.max_bytes = max_bytes
        self.size = size
        self.drop_oldest = drop_oldest
        self.waiting: deque[T] = deque()
        self.bytes = 0
        """The size of the items waiting."""
        self._task: asyncio.Task[None] | None = None

    @property
    def busy(self) -> bool:
        """Whether an item is being handled or waits: a new one must go behind it."""
        return self._task is not None

    def _full(self, size: int) -> bool:
        return bool(self.waiting) and (
            len(self.waiting) >= self.max_waiting
            or (self.max_bytes is not None and self.bytes + size > self.max_bytes))

    def push(self, item: T) -> int:
        """Queue ``item`` behind the others (call on the loop; the lane's task starts if it
        was idle); how many of the oldest were dropped to make room."""
        size = self.size(item)
        dropped = 0
        if self._full(size):
            if not self.drop_oldest:
                raise LaneFull(f"{len(self.waiting)} wait (at most {self.max_waiting})")
            while self._full(size):
                self.bytes -= self.size(self.waiting.popleft())
                dropped += 1
        self.waiting.append(item)
        self.bytes += size
        if self._task is None:
            self._task = asyncio.get_running_loop().create_task(self._run())
        return dropped

    async def _run(self) -> None:
        try:
            while self.waiting:
                item = self.waiting.popleft()
                self.bytes -= self.size(item)
                try:
                    await self.handle(item)
                except Exception:
                    log.exception("an ordered lane's handler failed; the lane goes on")
        finally:
            if self._task is asyncio.current_task():
                self._task = None

    def close(self) -> None:
        """The stream is gone: what waits is dropped, the item being handled abandoned."""
        self.waiting.clear()
        self.bytes = 0
        if self._task is not None:
            self._task.cancel()
            self._task = None
