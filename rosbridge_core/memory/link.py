"""A client's link in memory: frames in, frames out, no socket.

:class:`MemoryLink` is a :class:`~rosbridge_core.session.link.ClientLink` whose frames the
client hands over with :meth:`MemoryLink.receive` and whose outgoing frames (JSON text, or
CBOR bytes) go to the ``deliver`` callback given at its making, in the call that writes them.
It is :attr:`~MemoryLink.direct` and never :attr:`~MemoryLink.framing`: the outbox writes it
batches of whole frames, never websocket bytes. There is no keepalive (nothing can fall
silent) and no handshake: the headers are given.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections import deque
from collections.abc import AsyncIterator, Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

from rosbridge_core.session.frames import joined

if TYPE_CHECKING:
    from rosbridge_core.security.auth import Principal
    from rosbridge_core.session.frames import Frame

__all__ = ["LinkClosed", "MemoryLink"]


class LinkClosed(Exception):
    """The in-memory link has ended (what reading and writing raise then)."""


class _NoBytes:
    """The byte sink of a link that takes no ready frame bytes."""

    def write(self, data: bytes) -> None:
        raise LinkClosed("the in-memory link takes whole frames, not frame bytes")

    def writelines(self, list_of_data: Sequence[bytes]) -> None:
        raise LinkClosed("the in-memory link takes whole frames, not frame bytes")


class MemoryLink:
    """One in-memory client connection (see the module's text).

    ``deliver`` gets each frame the session writes, in order; ``on_close`` is told the code
    and reason when the session closes the link (not when :meth:`drop` does).
    """

    principal: Principal | None = None

    def __init__(self, deliver: Callable[[str | bytes], None], *,
                 headers: Mapping[str, str] | None = None,
                 on_close: Callable[[int, str], None] | None = None,
                 address: str = "memory:0") -> None:
        self._deliver = deliver
        self._headers = {k.lower(): v for k, v in (headers or {}).items()}
        self._on_close = on_close
        self._address = address
        self._handler: Callable[[str | bytes], None] | None = None
        self._waiting: deque[str | bytes] = deque()
        self._wake = asyncio.Event()
        self.closed = False
        self._by_client = False
        self.limit: int | None = None

    # -- what the session reads --------------------------------------------------------------------

    @property
    def direct(self) -> bool:
        """Frames may be written at any time."""
        return True

    @property
    def framing(self) -> bool:
        """The link takes whole frames, never websocket bytes."""
        return False

    @property
    def transport(self) -> _NoBytes:
        """No byte sink (never used: the link is not :attr:`framing`)."""
        return _NoBytes()

    @property
    def closed_errors(self) -> tuple[type[BaseException], ...]:
        """What reading and writing raise once the link has ended."""
        return (LinkClosed,)

    @property
    def address(self) -> str:
        """The client's address, as given."""
        return self._address

    @property
    def remote_address(self) -> Any:
        """The client's address as a (host, port) pair."""
        host, _, port = self._address.rpartition(":")
        return host, int(port or 0)

    @property
    def closed_by_client(self) -> bool:
        """Whether the client ended the link itself (:meth:`drop` with ``by_client``)."""
        return self._by_client

    def header(self, name: str) -> str | None:
        """A header the client "sent" (given at the making)."""
        return self._headers.get(name.lower())

    # -- frames in ---------------------------------------------------------------------------------

    def receive(self, frame: str | bytes) -> None:
        """The client sends ``frame``: handed to the session now when it takes frames so
        (:meth:`hand_frames_to`), else queued for its reading loop."""
        if self.closed:
            raise LinkClosed("the in-memory link has ended")
        if self._handler is not None and not self._waiting:
            self._handler(frame)
        else:
            self._waiting.append(frame)
            self._wake.set()

    def hand_frames_to(self, handler: Callable[[str | bytes], None] | None) -> None:
        """Hand frames to ``handler`` as they come (``None``: queue them again); the frames
        queued meanwhile are handed over first, in order."""
        self._handler = handler
        while handler is not None and self._waiting and self._handler is handler:
            handler(self._waiting.popleft())

    async def __aiter__(self) -> AsyncIterator[str | bytes]:
        """The frames not handed over, until the link ends."""
        while True:
            while self._waiting:
                yield self._waiting.popleft()
            if self.closed:
                return
            self._wake.clear()
            await self._wake.wait()

    def limit_frames(self, size: int | None) -> None:
        """Noted (the client's frames are not checked against it here: the session's gate
        counts frame sizes itself)."""
        self.limit = size

    # -- frames out --------------------------------------------------------------------------------

    def writable(self) -> bool:
        """Whether the link is open (it takes any amount at once)."""
        return not self.closed

    def raw_ok(self) -> bool:
        """Never: frames are whole frames."""
        return False

    def write(self, frames: list[Frame]) -> None:
        """Hand each frame to the client, in order (one in parts joined first)."""
        if self.closed:
            raise LinkClosed("the in-memory link has ended")
        deliver = self._deliver
        for frame in frames:
            deliver(joined(frame))

    @contextlib.asynccontextmanager
    async def send_context(self) -> AsyncIterator[None]:
        """Nothing to wait for: the link takes everything at once."""
        if self.closed:
            raise LinkClosed("the in-memory link has ended")
        yield

    async def close(self, code: int = 1000, reason: str = "") -> None:
        """The session closes the link: the client is told (``on_close``)."""
        if self.closed:
            return
        self._end()
        if self._on_close is not None:
            self._on_close(code, reason)

    def abort(self) -> None:
        """Drop the link at once."""
        self._end()

    def drop(self, *, by_client: bool = False) -> None:
        """The client's side ends the link (``by_client``: as a close frame would; else as a
        lost connection)."""
        self._by_client = by_client
        self._end()

    def _end(self) -> None:
        self.closed = True
        self._handler = None
        self._wake.set()

    # -- liveness ----------------------------------------------------------------------------------

    async def ping(self) -> asyncio.Future[float]:
        """Answered at once while open."""
        if self.closed:
            raise LinkClosed("the in-memory link has ended")
        answered: asyncio.Future[float] = asyncio.get_running_loop().create_future()
        answered.set_result(0.0)
        return answered

    def watch(self, interval: float, timeout: float, dead: Callable[[float], None]
              ) -> asyncio.Task[bool] | None:
        """No keepalive: an in-memory client cannot fall silent."""
        return None
