"""The inbound byte budget: what a connection has received and not yet handled, counted per
connection, in all, and (through the connection's :class:`Charges`, its
:class:`~rosbridge_core.security.accounts.Holder`'s) per principal and per address.

websockets reads frames into an ``Assembler`` with a frame queue; the bridge replaces both on
every server connection (:class:`~bridge_server.front.websocket.BridgeConnection`):
:class:`CountingQueue` counts the bytes queued, and the frames of a fragmented websocket
message that the reader has taken while its last frame has not come (websockets keeps them
in a list until then), and :class:`BudgetAssembler` stops reading the socket over the budget.
Like the rest of :mod:`bridge_server.front`, this builds on websockets' private internals
(:func:`~bridge_server.front.websocket.check_websockets_internals` checks them at start).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

from websockets.asyncio.messages import Assembler, SimpleQueue
from websockets.frames import Frame

__all__ = ["BudgetAssembler", "Charges", "CountingQueue", "Inbound"]


class Charges(Protocol):
    """Where a connection's in-flight bytes are charged across connections
    (:meth:`rosbridge_core.security.accounts.Holder.inflight`)."""

    def force(self, n: int) -> None:
        """Charge ``n`` bytes held already."""

    def give_back(self, n: int) -> None:
        """Release ``n`` bytes charged before."""

    def over(self) -> str | None:
        """Which limit what is charged is past now (``None``: none)."""


@dataclass
class Inbound:
    """Bytes queued by every connection of a bridge together."""

    bytes: int = 0


class CountingQueue(SimpleQueue[Frame]):
    """websockets' frame queue, counting the bytes it holds (per connection and in all), and
    charging them, with a fragmented message's frames until its last one is taken, as
    in-flight bytes to ``charges``."""

    def __init__(self, totals: Inbound, charges: Charges | None = None) -> None:
        super().__init__()
        self.totals = totals
        self.charges = charges
        self.bytes = 0
        self.partial = 0
        """Bytes of a fragmented message's frames taken by the reader, its last one not yet."""

    def put(self, item: Frame) -> None:
        """Queue a frame; count it."""
        n = len(item.data)
        self.bytes += n
        self.totals.bytes += n
        if self.charges is not None:
            self.charges.force(n)  # read already: the connection decides
        super().put(item)

    async def get(self, block: bool = True) -> Frame:
        """The next frame; a message's last frame releases the whole message's charge."""
        item = await super().get(block)
        n = len(item.data)
        self.bytes -= n
        self.totals.bytes -= n
        if not item.fin:
            self.partial += n
        else:
            if self.charges is not None:
                self.charges.give_back(self.partial + n)
            self.partial = 0
        return item

    def put_back(self, items: Any) -> None:
        """Frames the reader took are queued again (its wait was cancelled)."""
        n = sum(len(i.data) for i in items)
        self.bytes += n
        self.totals.bytes += n
        self.partial = max(0, self.partial - n)
        super().put_back(items)

    def abort(self) -> None:
        """The stream ended: nothing is counted any more."""
        self.totals.bytes -= self.bytes
        if self.charges is not None:
            self.charges.give_back(self.bytes + self.partial)
            self.charges = None
        self.bytes = self.partial = 0
        self.totals = Inbound()  # what is read after the end is no longer counted in all
        super().abort()


class BudgetAssembler(Assembler):
    """Pauses reading when a connection holds more than its byte budget (or all do, or the
    connections of its principal or address hold more than theirs)."""

    def __init__(self, budget: int, total_budget: int, totals: Inbound,
                 charges: Charges | None = None, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.frames = self.queue = CountingQueue(totals, charges)
        self.budget = budget
        self.total_budget = total_budget
        self.totals = totals

    def maybe_pause(self) -> None:
        """Pause reading the socket when a budget is passed."""
        if self.paused:
            return
        q = self.queue
        if (
            (self.high is not None and len(q) > self.high)
            or (self.budget and q.bytes > self.budget)
            or (self.total_budget and self.totals.bytes > self.total_budget)
            or (q.charges is not None and q.charges.over() is not None)
        ):
            self.paused = True
            self.pause()

    def maybe_resume(self) -> None:
        """Read again once the connection's own queue has drained."""
        if not self.paused:
            return
        q = self.queue
        if (self.low is None or len(q) <= self.low) and q.bytes <= self.budget // 4:
            self.paused = False
            self.resume()
