"""The seam between the client and a transport: ops go down, ops and events come up.

A transport never interprets the API: it moves :mod:`rosbridge_core.protocol.ops`
values. The client calls :meth:`Transport.encode` to check and freeze an op
(a frame: the JSON text for a socket, a private copy in memory), then
:meth:`Transport.write` to send it while connected; frames encoded while
offline are kept by the client and written after the next connect. Upward, the
transport calls the :class:`Link` hooks: every op that arrives, and each
change of the connection.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol

from rosbridge_core.protocol.ops import (
    ACKS_HEADER,  # re-exported: where transports have always found it
)

if TYPE_CHECKING:
    from rosbridge_core.protocol import ops

    from ..exceptions import ConnectionClosed

__all__ = ["ACKS_HEADER", "Link", "Transport"]

class Link(Protocol):
    """What a transport calls on the client that owns it."""

    def receive_op(self, op: ops.Op) -> None:
        """One op arrived (never raises)."""
        ...

    def link_up(self) -> None:
        """A connection is open: restore every handle, then report CONNECTED."""
        ...

    def link_down(self) -> None:
        """The connection dropped and a reconnect follows: fail what was in flight."""
        ...

    def shut_down(self, error: ConnectionClosed) -> None:
        """The connection is gone for good (state CLOSED)."""
        ...


class Transport(Protocol):
    """Carries ops to and from a bridge (see the module docstring)."""

    @property
    def url(self) -> str:
        """What this transport connects to (for error texts)."""

    acks: bool
    """The peer confirms each advertise/subscribe/advertise_service with a ``status``."""

    def bind(self, link: Link) -> None:
        """Attach the client; called once, before :meth:`start`."""
        ...

    @property
    def connected(self) -> bool:
        """True while frames can be written."""
        ...

    async def start(self) -> None:
        """Open the first connection (raises ConnectError / UsageError)."""
        ...

    def encode(self, op: ops.Op) -> Any:
        """Check ``op`` and freeze it into a frame (raises LocalProtocolError)."""
        ...

    def write(self, frame: Any) -> None:
        """Queue one frame from :meth:`encode` (only while :attr:`connected`)."""
        ...

    @property
    def backlog(self) -> int:
        """Frames queued but not yet written."""
        ...

    async def flush(self) -> None:
        """Return once every frame queued so far was written (or the connection dropped)."""
        ...

    async def close(self) -> None:
        """Stop for good (the client has already entered CLOSED)."""
        ...
