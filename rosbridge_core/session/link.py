"""What a session needs of its client's connection: the link port.

A :class:`~rosbridge_core.session.session.Session` (and a Foxglove one) reads frames from, and
writes frames to, a :class:`ClientLink`; it never sees the websocket library. The bridge's
link is its websocket connection
(:class:`~bridge_server.front.websocket.WebSocketLink`, the only code that
touches websockets' internals); MockRos and the session tests drive one over
:class:`~rosbridge_core.memory.link.MemoryLink` with no socket at all.

Sending has two speeds. A link that writes ready frame bytes itself (``framing``) lets the
outbox write a message's shared frame straight to its :attr:`ClientLink.transport` the moment
:meth:`ClientLink.writable` says it takes data, and frame batches itself
(:meth:`ClientLink.write`); every other link gets its frames in batches from the outbox's
writer task (:meth:`ClientLink.send_context` then :meth:`ClientLink.write`).
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Awaitable, Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from contextlib import AbstractAsyncContextManager

    from rosbridge_core.security.auth import Principal
    from rosbridge_core.session.frames import Frame

__all__ = ["ByteSink", "ClientLink", "LinkConfig"]


@dataclass(frozen=True)
class LinkConfig:
    """How a session treats its link (set from the command line): the largest frame, and the
    keepalive (0: none of the session's own)."""

    max_message_size: int
    keepalive_interval: float
    keepalive_timeout: float


class ByteSink(Protocol):
    """Where a framing link's ready bytes go (an asyncio transport)."""

    def write(self, data: bytes) -> None:
        """Write ``data`` (buffered when the peer does not take it yet)."""

    def writelines(self, list_of_data: Sequence[bytes]) -> None:
        """Write the pieces one after the other (no joined copy)."""


class ClientLink(Protocol):
    """One client's connection, as its session uses it."""

    principal: Principal | None
    """Who the client proved to be at the handshake (``None``: nobody yet)."""

    @property
    def direct(self) -> bool:
        """Whether frames may be written between the writer task's rounds (:meth:`writable`)."""

    @property
    def framing(self) -> bool:
        """Whether the link takes frames framed already (:class:`~.frames.Wire`) and its
        :attr:`transport` takes ready frame bytes: the outbox's fast path."""
    @property
    def transport(self) -> ByteSink:
        """Where ready frame bytes go (used only when :attr:`framing`)."""

    @property
    def closed_errors(self) -> tuple[type[BaseException], ...]:
        """What reading, writing and pinging raise once the connection has ended."""

    @property
    def address(self) -> str:
        """The client's address, ``host:port`` (for the log and the status page)."""

    @property
    def remote_address(self) -> Any:
        """The client's address as the socket gives it (the key of per-address limits)."""

    @property
    def closed_by_client(self) -> bool:
        """Whether the client ended the connection itself (a close frame, 1000 or 1001)."""

    def header(self, name: str) -> str | None:
        """A header of the client's handshake request (``None``: not sent)."""

    # -- receiving -------------------------------------------------------------------------------

    def __aiter__(self) -> AsyncIterator[str | bytes]:
        """The frames received, in order, until the connection ends (text: JSON, binary: CBOR)."""

    def hand_frames_to(self, handler: Callable[[str | bytes], None] | None) -> None:
        """Hand frames to ``handler`` as they are read, where the link can (``None``: stop);
        frames not handed over still come through the iteration, in order."""

    def limit_frames(self, size: int | None) -> None:
        """Refuse frames over ``size`` bytes from now on (``None``: the configured limit)."""

    # -- sending -----------------------------------------------------------------------------------

    def writable(self) -> bool:
        """Whether a write now goes out at once: open, nothing waiting to be written."""

    def raw_ok(self) -> bool:
        """Whether a batch may hold frames framed already (:class:`~.frames.Wire`)."""

    def write(self, frames: list[Frame]) -> None:
        """Write ``frames`` with one write (inside :meth:`send_context`, or when
        :meth:`writable`)."""

    def send_context(self) -> AbstractAsyncContextManager[None]:
        """Wait until the link takes more (flow control), and hold it for one :meth:`write`."""

    async def close(self, code: int = 1000, reason: str = "") -> None:
        """Close the connection with ``code`` and ``reason``."""

    def abort(self) -> None:
        """Drop the connection at once (no closing handshake)."""

    # -- liveness ----------------------------------------------------------------------------------

    async def ping(self) -> Awaitable[float]:
        """Ping the client; the result completes with the round trip when it answers."""

    def watch(self, interval: float, timeout: float, dead: Callable[[float], None]
              ) -> asyncio.Task[bool] | None:
        """Start the keepalive: a client silent for ``interval`` s is pinged and dropped if it
        answers nothing within ``timeout`` s (``dead`` is told how long it was silent);
        ``None`` where the link cannot be watched so (websockets' own pings stand in)."""
