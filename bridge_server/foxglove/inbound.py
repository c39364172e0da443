"""A Foxglove client's messages on one channel, decoded in order, the large ones off the loop.

A client's ``cdr`` message is decoded (:mod:`msgs.cdr`, within its
:class:`~msgs.cdr.Budget`) and converted for ROS before it is published. On the event loop,
a 16 MiB message of empty structs stopped every other client for 28.8 s (issue 53). Now a
message of :data:`~rosbridge_core.codec.budget.OFF_LOOP_BYTES` or more is decoded and
converted on a worker thread; the channel's later messages wait behind it (at most
:data:`WAITING`, past that refused with an error), and each is published on the loop in
the order it came. A small message on a channel with nothing waiting is handled at once,
as before.
"""

from __future__ import annotations

import asyncio
from collections import deque
from collections.abc import Callable
from typing import Any

from rosbridge_core.codec.budget import OFF_LOOP_BYTES, workers

__all__ = ["WAITING", "Inbound"]

WAITING = 4
"""Messages of one channel waiting to be decoded, at most (one more is refused)."""

Done = Callable[[Any, BaseException | None], None]
"""Called on the loop with the converted message, or with what went wrong."""


class Inbound:
    """One client channel's messages on their way to ROS (see the module text):
    ``convert(payload)`` is the decode and conversion, run on a worker thread for a large
    payload."""

    def __init__(self, convert: Callable[[bytes], Any]) -> None:
        self.convert = convert
        self.waiting: deque[tuple[bytes, Done]] = deque()
        self._task: asyncio.Task[None] | None = None

    def submit(self, payload: bytes, done: Done) -> str | None:
        """Convert ``payload`` and hand the result to ``done`` in order (now, for a small one
        with nothing waiting); why it was refused, or ``None``."""
        if self._task is None and len(payload) < OFF_LOOP_BYTES:
            try:
                msg = self.convert(payload)
            except Exception as exc:
                done(None, exc)
            else:
                done(msg, None)
            return None
        if len(self.waiting) >= WAITING:
            return (f"{len(self.waiting)} large messages of this channel wait to be decoded "
                    f"(at most {WAITING}): this one is dropped")
        self.waiting.append((payload, done))
        if self._task is None:
            self._task = asyncio.get_running_loop().create_task(self._run())
        return None

    async def _run(self) -> None:
        loop = asyncio.get_running_loop()
        try:
            while self.waiting:
                payload, done = self.waiting.popleft()
                try:
                    if len(payload) < OFF_LOOP_BYTES:
                        msg = self.convert(payload)
                    else:
                        msg = await loop.run_in_executor(workers(), self.convert, payload)
                except Exception as exc:
                    done(None, exc)
                else:
                    done(msg, None)
        finally:
            if self._task is asyncio.current_task():
                self._task = None

    def close(self) -> None:
        """The channel is gone: what waits is dropped."""
        self.waiting.clear()
        if self._task is not None:
            self._task.cancel()
            self._task = None
