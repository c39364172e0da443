"""With ``--workers``: a session resume reaches its session whichever worker takes the reconnect.

A kept session lives in the worker that opened it, and its token names that worker
(:func:`rosbridge_core.session.resume.worker_of`); the kernel hands a reconnect to any
worker. So each worker also serves websockets on a unix socket, ``D/forward-<i>.sock``,
with the same handler and the same admission checks as its port. A worker whose port
receives a resume naming another worker answers nothing itself (:meth:`Forwarder.
process_request`): it opens the owner's socket, writes the client's handshake request there
as received, and once the owner has answered it takes the connection's transport from
websockets (after TLS, so the bytes are plain) and copies bytes both ways, the owner's
answer first, closing each side when the other closes and pausing each side's reading
while the other cannot take more.

The owner admits the forwarded request exactly as one from its own port (origin, client
limits, lock-out, token, the session's principal), so a forged forward gains nothing a
direct connection would not. The client's address travels in :data:`FORWARDED_HEADER`,
which only the unix socket honours (the port never reads it; a client that sends it has
it replaced); it is what the owner's logs and per-address limits see. The socket lives in
the supervisor's private directory (mode 0700), so only the bridge's user can reach it.

A resume naming a worker that is not there (none of that index, or restarting), or one that
closes the forwarded connection unanswered (killed meanwhile) or does not answer within
:data:`ANSWER_WAIT`, is served where it landed, as any unknown token is: a new session.

Only resumes that land on the wrong worker take the extra hop; the token says where the
session is, so nothing is shared between workers but these sockets.
"""

from __future__ import annotations

import asyncio
import logging
import os
from collections.abc import Awaitable, Callable
from typing import Any

from websockets.asyncio.server import Server, ServerConnection, unix_serve
from websockets.datastructures import Headers
from websockets.http11 import Request, Response

from bridge_server.front.websocket import BridgeConnection, take_transport
from bridge_server.workers.peers import PEER_TIMEOUT
from rosbridge_core.protocol.ops import SESSION_HEADER
from rosbridge_core.session.resume import CLAIM_WAIT, worker_of

__all__ = ["ANSWER_WAIT", "FORWARDED_HEADER", "Forwarder", "forward_path"]

log = logging.getLogger("bridge_server.http.forward")

FORWARDED_HEADER = "X-Bridge-Forwarded-For"
"""The client's ``address:port``, written by the forwarding worker; honoured only on the
forwarded listener."""

ANSWER_WAIT = CLAIM_WAIT + 2 * PEER_TIMEOUT
"""Seconds a forwarded resume waits for the owner's answer (which may wait
:data:`~rosbridge_core.session.resume.CLAIM_WAIT` for the session's old link) before it is
served where it landed."""

Admit = Callable[[ServerConnection, Request], Awaitable[Response | None]]


def forward_path(directory: str, index: int) -> str:
    """The unix socket on which worker ``index`` takes forwarded connections."""
    return os.path.join(directory, f"forward-{index}.sock")


class Forwarder:
    """One worker's half of forwarding: hands other workers' resumes over, takes its own."""

    def __init__(self, directory: str, index: int, admit: Admit) -> None:
        """``admit``: the bridge's checks before a handshake (``process_request``)."""
        self.directory = directory
        self.index = index
        self.admit = admit
        self.links: set[asyncio.Transport] = set()  # clients' transports being forwarded
        self.server: Server | None = None
        self.forwarded = 0  # resumes handed over (sessions_forwarded_total in /metrics)

    async def serve(self, handler: Callable[[ServerConnection], Awaitable[None]],
                    **kwargs: Any) -> None:
        """Take forwarded connections on this worker's unix socket: ``handler`` and
        ``kwargs`` as for the port (without TLS: the forwarding worker ended it)."""
        path = forward_path(self.directory, self.index)
        if os.path.exists(path):
            os.unlink(path)  # left by a worker of this index that died
        kwargs["ssl"] = None
        self.server = await unix_serve(handler, path,
                                       process_request=self._admit_forwarded, **kwargs)

    async def process_request(self, connection: ServerConnection, request: Request
                              ) -> Response | None:
        """The port's ``process_request``: a resume of another worker's session goes there
        (websockets then answers nothing), anything else is admitted here."""
        tokens = request.headers.get_all(SESSION_HEADER)
        owner = worker_of(tokens[0]) if len(tokens) == 1 else None
        if owner is not None and owner != self.index and await self._hand_over(
                connection, request, owner):
            return connection.respond(421, f"forwarded to worker {owner}\n")  # never sent
        return await self.admit(connection, request)

    async def _hand_over(self, connection: ServerConnection, request: Request,
                         owner: int) -> bool:
        """Pipe ``connection`` to worker ``owner`` once that worker has answered its request;
        False if it cannot be reached or closes without an answer (the resume is then
        served here)."""
        client = connection.transport
        loop = asyncio.get_running_loop()
        peer = connection.remote_address
        address = f"{peer[0]}:{peer[1]}" if isinstance(peer, tuple) else str(peer)
        headers = Headers([(k, v) for k, v in request.headers.raw_items()
                           if k.lower() != FORWARDED_HEADER.lower()])
        headers[FORWARDED_HEADER] = address
        owner_side = _Pipe(None, loop)
        try:
            async with asyncio.timeout(PEER_TIMEOUT):
                unix, _ = await loop.create_unix_connection(
                    lambda: owner_side, forward_path(self.directory, owner))
        except (OSError, TimeoutError) as exc:
            log.info("a session resume names worker %d, which cannot be reached (%s): "
                     "served here", owner, exc)
            return False
        answered = False
        try:
            unix.write(Request(request.path, headers).serialize())
            async with asyncio.timeout(ANSWER_WAIT):
                answered = await owner_side.answered
        except TimeoutError:
            pass
        finally:
            if not answered or client.is_closing():
                unix.abort()
        if not answered:
            log.info("worker %d did not answer a forwarded session resume (stopping or "
                     "stuck): served here", owner)
            return False
        if client.is_closing():  # the client left meanwhile
            return True
        take_transport(connection)
        self.links.add(client)
        client.set_protocol(_Pipe(unix, loop, lambda: self.links.discard(client)))
        owner_side.pipe_to(client)
        self.forwarded += 1
        log.info("forwarded a session resume from %s to worker %d", address, owner)
        return True

    async def _admit_forwarded(self, connection: ServerConnection, request: Request
                               ) -> Response | None:
        """The forwarded listener's ``process_request``: the client's address from
        :data:`FORWARDED_HEADER`, then the same checks as on the port."""
        values = request.headers.get_all(FORWARDED_HEADER)
        host, _, port = values[0].rpartition(":") if len(values) == 1 else ("", "", "")
        if not host or not port.isdecimal() or not isinstance(connection, BridgeConnection):
            return connection.respond(400, f"a forwarded request needs one {FORWARDED_HEADER} "
                                           "header (host:port)\n")
        connection.forwarded_from = (host, int(port))
        return await self.admit(connection, request)

    def close(self) -> None:
        """Cut the connections being forwarded to other workers (the bridge closes
        :attr:`server` with its port)."""
        for client in list(self.links):
            client.abort()


class _Pipe(asyncio.Protocol):
    """One side of a forwarded connection: what it reads goes to the other side's transport.

    The owner's side starts with no other side: it holds what it reads until the owner's
    handshake answer is whole (:attr:`answered` True; False if the owner closes first),
    and pipes from :meth:`pipe_to` on.
    """

    def __init__(self, to: asyncio.Transport | None, loop: asyncio.AbstractEventLoop,
                 lost: Callable[[], None] | None = None) -> None:
        self.to = to
        self.lost = lost
        self.held = bytearray()
        self.answered: asyncio.Future[bool] = loop.create_future()

    def pipe_to(self, to: asyncio.Transport) -> None:
        """From now on write to ``to``, first what was held."""
        self.to = to
        to.write(bytes(self.held))
        self.held.clear()

    def data_received(self, data: bytes) -> None:
        if self.to is not None:
            self.to.write(data)
            return
        self.held += data
        if not self.answered.done() and b"\r\n\r\n" in self.held:
            self.answered.set_result(True)

    def eof_received(self) -> bool:
        return False  # the transport closes; connection_lost closes the other side

    def connection_lost(self, exc: Exception | None) -> None:
        if not self.answered.done():
            self.answered.set_result(False)
        if self.to is not None:
            self.to.close()  # after writing what it holds (a close frame, say)
        if self.lost is not None:
            self.lost()

    def pause_writing(self) -> None:  # this side cannot take more: stop reading the other
        if self.to is not None and not self.to.is_closing():
            self.to.pause_reading()

    def resume_writing(self) -> None:
        if self.to is not None and not self.to.is_closing():
            self.to.resume_reading()
