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

from collections.abc import Callable
from typing import Any

from rosbridge_core.codec.budget import OFF_LOOP_BYTES
from rosbridge_core.codec.lane import LaneFull, OrderedLane, off_loop

__all__ = ["WAITING", "Inbound"]

WAITING = 4
"""Messages of one channel waiting to be decoded, at most (one more is refused)."""

Done = Callable[[Any, BaseException | None], None]
"""Called on the loop with the converted message, or with what went wrong."""


class Inbound:
    """One client channel's messages on their way to ROS (see the module text):
    ``convert(payload)`` is the decode and conversion, run on a worker thread for a large
    payload; the order is kept by an :class:`~rosbridge_core.codec.lane.OrderedLane`."""

    def __init__(self, convert: Callable[[bytes], Any]) -> None:
        self.convert = convert
        self.lane: OrderedLane[tuple[bytes, Done]] = OrderedLane(
            self._handle, max_waiting=WAITING)

    def submit(self, payload: bytes, done: Done) -> str | None:
        """Convert ``payload`` and hand the result to ``done`` in order (now, for a small one
        with nothing waiting); why it was refused, or ``None``."""
        if not self.lane.busy and len(payload) < OFF_LOOP_BYTES:
            self._convert_now(payload, done)
            return None
        try:
            self.lane.push((payload, done))
        except LaneFull:
            return (f"{len(self.lane.waiting)} large messages of this channel wait to be "
                    f"decoded (at most {WAITING}): this one is dropped")
        return None

    def _convert_now(self, payload: bytes, done: Done) -> None:
        try:
            msg = self.convert(payload)
        except Exception as exc:
            done(None, exc)
        else:
            done(msg, None)

    async def _handle(self, item: tuple[bytes, Done]) -> None:
        payload, done = item
        if len(payload) < OFF_LOOP_BYTES:
            self._convert_now(payload, done)
            return
        try:
            msg = await off_loop(self.convert, payload)
        except Exception as exc:
            done(None, exc)
        else:
            done(msg, None)

    def close(self) -> None:
        """The channel is gone: what waits is dropped."""
        self.lane.close()
