"""The websocket front's connection: the only code that builds on websockets' private
internals. A connection is its session's link (:class:`WebSocketLink`, a
:class:`~rosbridge_core.session.link.ClientLink`: frames straight to the transport, one write
for a batch, the keepalive), with the inbound byte budget and the frames handed to the
session as they are read (:class:`BridgeConnection`).

websockets reads frames into an ``Assembler`` with a frame queue; the bridge replaces both
on every server connection (:class:`BridgeConnection`) so that the bytes waiting to be
handled are counted per connection and in all, and reading stops over the budget.

A session handles each frame at once and never waits while doing so, so a whole message
in one frame with nothing queued before it is handed to the session right where
websockets parsed it (:meth:`BridgeConnection.hand_frames_to`), instead of going through
the queue and a turn of the loop to wake the session's reading task: that was a third
of a client's reply's time in the bridge on its way to a ROS caller. Anything else (a
message in several frames, frames queued behind others, invalid UTF-8) takes websockets'
own path, so the order of messages and the closing rules stay websockets'.

While websockets' parser waits at a frame boundary with nothing buffered, the bytes read are
not even given to it: :meth:`BridgeConnection.data_received` reads the whole, final, masked
text and binary frames at their start itself (a header, a mask, websockets' own C unmasking)
and hands each over; websockets' parser, its frame objects and its event list were most
of the rest of that reply's Python. It stops at the first byte it does not take (a control
or continuation frame, reserved bits, a frame too large or cut off by the read, invalid
UTF-8, a handler that closed the connection) and gives websockets everything from there, at
a frame boundary, so websockets decides about those bytes exactly as before.
:func:`check_websockets_internals` fails at start-up, naming the version, if a websockets
upgrade changed what this relies on: an upgrade touches this file and nothing else.

With ``--workers``, a worker hands a session resume that another worker keeps to that
worker before answering its handshake: :func:`take_transport` takes the (decrypted)
transport from its websockets connection (tests/load/test_resume_workers.py holds it to
websockets' handshake), and :attr:`BridgeConnection.forwarded_from` gives the owning
worker's connection the client's real address.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import random
import socket
import struct
from collections.abc import Awaitable, Callable
from typing import TYPE_CHECKING, Any, Protocol

from websockets.asyncio.server import ServerConnection
from websockets.exceptions import ConnectionClosed
from websockets.frames import BINARY, TEXT, CloseCode, Frame
from websockets.protocol import OPEN
from websockets.streams import StreamReader

from rosbridge_core.protocol import keepalive

try:  # websockets' own unmasking, in C where it was built with it
    from websockets.speedups import apply_mask
except ImportError:  # pragma: no cover - a websockets without its C extension
    from websockets.utils import apply_mask

from bridge_server.front.budget import BudgetAssembler, Inbound
from rosbridge_core.interfaces import BridgeError
from rosbridge_core.protocol.constants import INTERNAL_ERROR
from rosbridge_core.session.frames import JOINED_BYTES, frame_parts, joined

log = logging.getLogger("bridge_server.security")

if TYPE_CHECKING:
    from rosbridge_core.security.accounts import Accounts, Holder, KindBudget
    from rosbridge_core.security.auth import Principal
    from rosbridge_core.security.options import SecurityConfig
    from rosbridge_core.session.frames import Frame as OutFrame


class ConnectionLimits(Protocol):
    """What a connection needs of the bridge's security: its limits, the bytes held by every
    connection, and being told when it ends (:class:`~rosbridge_core.security.Security`)."""

    config: SecurityConfig
    inbound: Inbound
    accounts: Accounts

    def release(self, connection: BridgeConnection) -> None:
        """A counted connection ended."""

__all__ = [
    "WEBSOCKETS_TESTED",
    "BridgeConnection",
    "BudgetAssembler",
    "ConnectionLimits",
    "Inbound",
    "WebSocketLink",
    "check_websockets_internals",
    "take_transport",
]


_CLOSED_ERRORS: tuple[type[BaseException], ...] = (ConnectionClosed,)


class WebSocketLink(ServerConnection):
    """A websockets server connection as a session's
    :class:`~rosbridge_core.session.link.ClientLink`: frames straight to the transport, one
    write for a batch (:meth:`write`), the keepalive (:meth:`watch`)."""

    principal: Principal | None = None
    on_frame: Callable[[str | bytes], None] | None = None

    def hand_frames_to(self, handler: Callable[[str | bytes], None] | None) -> None:
        """Hand each whole message with nothing queued before it to ``handler`` as it is
        read (``None``: every message waits for ``recv`` again). ``handler`` must not block;
        what it raises is logged and the connection closed (1011)."""
        self.on_frame = handler

    def limit_frames(self, size: int | None) -> None:
        """Refuse frames over ``size`` bytes from the next frame header on (``None``: the
        configured ``max_size`` again). Set before the handshake response, it covers the
        first frame too: a client announcing a bigger frame is closed (1009) at its header,
        before the bridge holds any of it."""
        protocol = self.protocol
        if not hasattr(self, "_max_size"):
            self._max_size = protocol.max_message_size
        protocol.max_message_size = self._max_size if size is None else size

    # -- the link port (rosbridge_core.session.link.ClientLink) ---------------------------------

    closed_errors = _CLOSED_ERRORS

    @property
    def address(self) -> str:
        """The client's address, ``host:port``."""
        addr = self.remote_address
        if isinstance(addr, tuple) and len(addr) >= 2:
            return f"{addr[0]}:{addr[1]}"
        return str(addr)

    @property
    def direct(self) -> bool:
        """Frames may be written between the writer's rounds (straight to the transport)."""
        return self.transport is not None

    @property
    def framing(self) -> bool:
        """Frames may be framed by the outbox (no extension, no frame logging)."""
        return not self.protocol.extensions and not self.protocol.debug

    @property
    def closed_by_client(self) -> bool:
        """Whether the client sent a close frame with 1000 or 1001."""
        received = self.protocol.close_rcvd
        return received is not None and received.code in (1000, 1001)

    def header(self, name: str) -> str | None:
        """A header of the handshake request."""
        request = self.request
        return None if request is None else request.headers.get(name)

    def writable(self) -> bool:
        """Open, websockets holding nothing back, the transport's buffer empty."""
        protocol = self.protocol
        transport = self.transport
        return not (
            protocol.state is not OPEN
            or protocol.writes
            or protocol.expect_continuation_frame
            or transport.get_write_buffer_size()
            or transport.is_closing()
        )

    def raw_ok(self) -> bool:
        """Whether frames may be written framed here (no extension, open, websockets not in
        the middle of a fragmented message and holding nothing back, and not logging each
        frame)."""
        protocol = self.protocol
        return (
            not protocol.extensions
            and protocol.state is OPEN
            and not protocol.expect_continuation_frame
            and not protocol.writes
            and not protocol.debug  # websockets logs each frame it makes
        )

    def write(self, frames: list[OutFrame]) -> None:
        """Write several frames with one socket write (one system call, not one per frame).

        The outbox's writer calls it inside websockets' own send context, so its state
        checks, flow control (``write_limit``) and closing rules apply as for ``send``; the
        outbox otherwise only when :meth:`writable`. Without an extension
        (``--compression deflate``) the frames are made here
        (:func:`~rosbridge_core.session.frames.frame_parts`), with one websockets makes them.
        """
        if not frames:
            return
        transport = self.transport
        if self.raw_ok():
            parts = frame_parts(frames)
            if len(parts) == 1 or sum(map(len, parts)) <= JOINED_BYTES:
                transport.write(b"".join(parts))
            else:  # a big frame's payload is not copied into a joined buffer (uvloop)
                transport.writelines(parts)
            return
        protocol = self.protocol
        for frame in frames:
            payload = joined(frame)
            if isinstance(payload, str):
                protocol.send_text(payload.encode())
            else:
                protocol.send_binary(payload)  # never a Wire: framed only for raw_ok
        chunks = protocol.data_to_send()
        if all(chunks):
            transport.write(b"".join(chunks))
        else:  # an end-of-stream marker: let websockets handle these chunks itself
            for chunk in chunks:
                if chunk:
                    transport.write(chunk)
                elif transport.can_write_eof():
                    transport.write_eof()

    def abort(self) -> None:
        """Drop the connection at once."""
        self.transport.abort()

    def watch(self, interval: float, timeout: float, dead: Callable[[float], None]
              ) -> asyncio.Task[bool] | None:
        """The keepalive where TCP tells when the peer was last heard
        (:func:`rosbridge_core.protocol.keepalive.watch`, pinging with :meth:`ping_now`);
        ``None`` elsewhere, or with ``interval`` 0."""
        transport = self.transport
        if not interval or transport is None or not keepalive.supported_here():
            return None
        return asyncio.create_task(keepalive.watch(transport, self.ping_now, dead, interval,
                                                   timeout))

    def ping_now(self) -> Awaitable[Awaitable[float]] | asyncio.Future[float]:
        """A ping written at once, its pong's future returned, where nothing waits to be
        written (websockets' ``ping`` is a coroutine: a task a ping, which with 5,000
        quiet connections was a tenth of a relay's samples); websockets' ``ping``
        otherwise. The pong resolves the future as websockets' own ping's (its
        ``pending_pings``)."""
        if not self.writable():
            return self.ping()
        pending = self.pending_pings
        data = struct.pack("!I", random.getrandbits(32))
        while data in pending:
            data = struct.pack("!I", random.getrandbits(32))
        pong: asyncio.Future[float] = self.loop.create_future()
        pending[data] = (pong, self.loop.time())
        self.protocol.send_ping(data)
        self.send_data()
        return pong


class BridgeConnection(WebSocketLink):
    """A server connection with an inbound byte budget and the principal it proved to be,
    which hands the frames it reads to its session as they are read."""

    security: ConnectionLimits

    counted: str | None = None
    forwarded_from: tuple[str, int] | None = None
    """The client's address, for a connection another worker forwarded (see
    :mod:`bridge_server.front.forward`): set only by the forwarded listener."""

    @property
    def remote_address(self) -> Any:
        """The client's address: the forwarding worker's word for a forwarded connection,
        else the socket's peer."""
        return self.forwarded_from or super().remote_address

    holder: Holder | None = None
    """This connection's share of the per-principal and per-address accounts (set when the
    handshake admits it: :meth:`hold`)."""
    _inflight: KindBudget | None = None
    _buffered = 0  # the bytes of an incomplete frame in websockets' reader, charged

    def hold(self, holder: Holder) -> None:
        """Charge what this connection holds to ``holder`` from now on: its fragments
        (through the session) and its in-flight bytes (the frames queued and those of an
        incomplete message, in the queue and in websockets' reader)."""
        self.holder = holder
        self._inflight = holder.inflight()
        assembler = self.recv_messages
        if isinstance(assembler, BudgetAssembler):
            assembler.queue.charges = self._inflight

    def data_received(self, data: bytes) -> None:
        """websockets' hook for the bytes read (:meth:`_read`); then what an incomplete
        message holds is charged, and the connection closed (1009) if that passes its
        principal's or its address's limit of in-flight bytes."""
        self._read(data)
        charges = self._inflight
        if charges is not None:
            protocol = self.protocol
            # nothing to charge or give back when no incomplete message is, or was, held
            if protocol.reader.buffer or self._buffered or protocol.current_size is not None:
                self._charge_incomplete(charges)

    def _charge_incomplete(self, charges: KindBudget) -> None:
        protocol = self.protocol
        buffered = len(protocol.reader.buffer)
        if buffered != self._buffered:
            if buffered > self._buffered:
                charges.force(buffered - self._buffered)
            else:
                charges.give_back(self._buffered - buffered)
            self._buffered = buffered
        if protocol.state is not OPEN or (not buffered and protocol.current_size is None):
            return  # no incomplete message held
        why = charges.over()
        if why is not None:
            log.warning("client from %s: closing (1009): %s", charges.holder.address, why)
            protocol.fail(CloseCode.MESSAGE_TOO_BIG, why.encode()[:123].decode(errors="ignore"))
            self.send_data()

    def _read(self, data: bytes) -> None:
        """At a frame boundary, the whole final masked text and binary frames ``data``
        starts with go to the frame handler, read here; the rest, from the first frame not
        taken, to websockets (see the module's docstring)."""
        handler = self.on_frame
        if handler is None or not self._at_frame_boundary():
            self._to_websockets(data)
            return
        protocol = self.protocol
        limit = protocol.max_message_size
        end = len(data)
        start = 0
        while end - start >= 6:
            head = data[start]
            second = data[start + 1]
            # FIN, no reserved bits, text (0x81) or binary (0x82); masked, as from a client
            if (head != 0x81 and head != 0x82) or second < 0x80:
                break
            size = second & 0x7F
            at = start + 2
            if size == 126:
                size = int.from_bytes(data[at:at + 2])
                at += 2
            elif size == 127:
                size = int.from_bytes(data[at:at + 8])
                at += 8
            if (limit is not None and size > limit) or at + 4 + size > end:
                break  # too large (websockets closes with 1009), or not all read yet
            payload = apply_mask(data[at + 4:at + 4 + size], data[at:at + 4])
            if head == 0x81:
                try:
                    message: str | bytes = payload.decode()
                except UnicodeDecodeError:  # websockets closes the connection (1007) for it
                    break
            else:
                message = payload
            start = at + 4 + size
            if not self._hand(handler, message) or self.on_frame is not handler \
                    or protocol.state is not OPEN:
                break
        if start < end:
            self._to_websockets(data[start:] if start else data)

    def _to_websockets(self, data: bytes) -> None:
        """Give ``data`` to websockets' parser, which may then wait anywhere in a frame."""
        self._waiting_parser = None
        super().data_received(data)

    _waiting_parser: Any = None
    """websockets' parser, seen waiting for a frame's first byte and given no byte since (it
    moves only when fed, and failing the connection replaces it): its chain of generators is
    not walked again for each read while the frames read are all taken here."""

    def _at_frame_boundary(self) -> bool:
        """Whether the next byte read starts a frame that :meth:`data_received` may read itself:
        open, no extension, no fragmented message under way, no frame queued for ``recv``,
        no debug log of frames, and websockets' parser waiting for a frame's first byte."""
        protocol = self.protocol
        if (protocol.state is not OPEN or protocol.extensions or protocol.debug
                or protocol.current_size is not None or protocol.max_fragment_size is not None
                or protocol.reader.buffer or self.recv_messages.frames.queue
                or self.recv_messages.closed):
            return False
        parser = protocol.parser
        if parser is not self._waiting_parser:
            if _innermost(parser) is not _AT_EOF:
                return False
            self._waiting_parser = parser
        return True

    def _hand(self, handler: Callable[[str | bytes], None], data: str | bytes) -> bool:
        """``handler(data)``; False if it raised (logged, the connection closed with 1011)."""
        try:
            handler(data)
        except Exception:
            log.exception("a frame handler failed; closing the connection")
            self.on_frame = None
            self.loop.create_task(self.close(INTERNAL_ERROR, "internal error"))
            return False
        return True

    def process_event(self, event: Any) -> None:
        """websockets' hook for each frame read: a whole text or binary message goes to the
        frame handler when nothing is queued before it; anything else to websockets."""
        handler = self.on_frame
        if (
            handler is not None
            and event.fin
            and (event.opcode is TEXT or event.opcode is BINARY)
            and not self.recv_messages.frames.queue
            and not self.recv_messages.closed
        ):
            try:
                data: str | bytes = (
                    event.data.decode() if event.opcode is TEXT else bytes(event.data)
                )
            except UnicodeDecodeError:  # websockets closes the connection (1007) for it
                super().process_event(event)
                return
            self._hand(handler, data)
            return
        super().process_event(event)

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        """websockets' hook: read frames through the budgeted assembler, and keep the
        kernel's unsent bytes for this client small (:func:`limit_unsent`)."""
        super().connection_made(transport)
        limit_unsent(transport, self.security.config.notsent_lowat)
        sec = self.security
        if protocol_size := self.protocol.max_message_size:
            sec.accounts.message_size = protocol_size  # the defaults are multiples of it
        self.recv_messages = BudgetAssembler(
            sec.config.inbound_budget,
            sec.config.inbound_budget_total,
            sec.inbound,
            high=self.max_queue_high,
            low=self.max_queue_low,
            pause=self.transport.pause_reading,
            resume=self.transport.resume_reading,
        )

    def connection_lost(self, exc: Exception | None) -> None:
        """websockets' hook: no longer count this connection against the client limits.

        The exception that ended websockets' parser (the end of the stream, mostly) keeps
        its traceback, whose frame is the parser's, holding the last frame read (up to
        ``--max-message-size``) in a reference cycle with the protocol: freed only when the
        cyclic collector runs (measured: 4 connections that each sent a 15.9 MB frame and
        dropped kept +61 to +91 MiB). The traceback is dropped here, so the frame goes with the
        connection.
        """
        super().connection_lost(exc)
        parser_exc = self.protocol.parser_exc
        if parser_exc is not None:
            parser_exc.__traceback__ = None
        self.security.release(self)


class _TakenAway(asyncio.Transport):
    """What a websockets connection holds after :func:`take_transport`: writes, closes and
    aborts go nowhere (the real transport serves another protocol now)."""

    def write(self, data: Any) -> None:
        """Dropped."""

    def close(self) -> None:
        """Nothing to close."""

    def abort(self) -> None:
        """Nothing to abort."""

    def is_closing(self) -> bool:
        """Always: nothing goes through here."""
        return True


def take_transport(connection: ServerConnection) -> asyncio.Transport:
    """Take ``connection``'s transport during its handshake (from ``process_request``) for
    another protocol, which the caller sets on it. websockets then sees a connection lost
    before its handshake: it answers nothing and leaves the transport alone.

    A client sends nothing after its handshake request until it is answered (RFC 6455,
    4.1), so no byte read so far is left behind in websockets' buffers.
    """
    transport = connection.transport
    connection.transport = _TakenAway()
    connection.connection_lost(None)
    return transport


_AT_EOF = StreamReader.at_eof.__code__
"""What websockets' parser waits in between two frames (``parse``: ``yield from at_eof()``)."""


def _innermost(generator: Any) -> Any:
    """The code of the generator ``generator`` waits in, through its ``yield from`` chain
    (websockets' server parser: the handshake's, then the frames', then the reader's)."""
    while (inner := getattr(generator, "gi_yieldfrom", None)) is not None:
        generator = inner
    return getattr(generator, "gi_code", None)


TCP_NOTSENT_LOWAT = getattr(socket, "TCP_NOTSENT_LOWAT", 25)  # Linux's value; 3.11 lacks it


def limit_unsent(transport: asyncio.BaseTransport, lowat: int) -> None:
    """Let the kernel hold at most about ``lowat`` unsent bytes for this connection.

    Without it the send buffer autotunes to megabytes, and on a slow link several camera
    frames wait in the kernel where no drop policy reaches them: ``queue_length`` and
    ``throttle_rate`` would drop nothing while the frames delivered grow ever older. With
    it, what the link cannot carry yet waits in the bridge's own per-subscription queue,
    which keeps the newest. 0 leaves the kernel's default.
    """
    sock = transport.get_extra_info("socket")
    if not lowat or sock is None or sock.family not in (socket.AF_INET, socket.AF_INET6):
        return
    with contextlib.suppress(OSError):  # not Linux, or not TCP: the kernel's default stays
        sock.setsockopt(socket.IPPROTO_TCP, TCP_NOTSENT_LOWAT, lowat)


WEBSOCKETS_TESTED = ">=17,<18"
"""The websockets versions whose internals :class:`BudgetAssembler` is tested with."""


def check_websockets_internals() -> None:
    """Fail at start-up, clearly, if websockets' private internals differ from what the byte
    budget builds on (its ``Assembler``, ``SimpleQueue`` and the connection's queue limits).

    Call with an event loop running. Raises :class:`BridgeError` naming the version.
    """
    from importlib.metadata import version

    from websockets.asyncio.connection import Connection
    from websockets.frames import Opcode
    from websockets.server import ServerProtocol

    try:
        totals = Inbound()
        asm = BudgetAssembler(1, 1, totals, high=4, low=1)
        asm.put(Frame(Opcode.TEXT, b"xy"))
        held = (totals.bytes, asm.paused, asm.frames is asm.queue and len(asm.frames.queue) == 1)
        asm.close()
        conn = Connection(ServerProtocol())
        limits = (conn.max_queue_high, conn.max_queue_low)
        problem = None if held == (2, True, True) and totals.bytes == 0 else f"counted {held}"
        if not hasattr(Connection, "connection_made") or len(limits) != 2:
            problem = "no connection_made or queue limits"
        elif not hasattr(Connection, "process_event") or not hasattr(asm, "closed"):
            problem = "no process_event or Assembler.closed (the frames handed over as read)"
        elif not isinstance(getattr(ServerProtocol(), "max_message_size", None), int):
            problem = "no protocol.max_message_size (the pre-authentication frame limit)"
        elif not all(hasattr(ServerProtocol(), a) for a in ("parser_exc", "current_size")):
            problem = "no protocol.parser_exc or current_size (what a connection holds)"
        elif not isinstance(getattr(conn, "pending_pings", None), dict):
            problem = "no pending_pings (the keepalive's pings, written at once)"
        elif not _parser_waits_at_eof():
            problem = "the parser does not wait in StreamReader.at_eof between frames"
    except Exception as exc:
        problem = f"{type(exc).__name__}: {exc}"
    if problem is not None:
        raise BridgeError(
            f"websockets {version('websockets')} is not supported by the bridge: its inbound "
            f"byte budget (bridge_server/front.py) builds on "
            f"websockets' private Assembler internals, tested with "
            f"websockets{WEBSOCKETS_TESTED} ({problem}); install "
            f"'websockets{WEBSOCKETS_TESTED}'"
        )


def _parser_waits_at_eof() -> bool:
    """Whether an open server protocol's parser waits where :meth:`BridgeConnection.
    data_received` looks for a frame boundary, after a handshake and after a whole frame."""
    from websockets.client import ClientProtocol
    from websockets.http11 import Request
    from websockets.server import ServerProtocol
    from websockets.uri import parse_uri

    client = ClientProtocol(parse_uri("ws://localhost/"))
    server = ServerProtocol()
    client.send_request(client.connect())
    server.receive_data(b"".join(client.data_to_send()))
    request = server.events_received()[0]
    assert isinstance(request, Request)
    server.send_response(server.accept(request))
    client.receive_data(b"".join(server.data_to_send()))
    client.send_text(b"{}")
    server.receive_data(b"".join(client.data_to_send()))
    return (
        server.state is OPEN
        and [getattr(e, "data", None) for e in server.events_received()] == [b"{}"]
        and not server.reader.buffer and server.current_size is None
        and server.max_fragment_size is None and not server.extensions
        and _innermost(server.parser) is _AT_EOF
    )
