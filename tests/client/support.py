"""A scripted rosbridge peer on a loopback socket, for the client's wire-level tests.

It is not a bridge: it records every op the client sends, lets the test send
any op back, and can drop the connection or stop listening, so the client's
I/O, state machine and reconnects are tested over a real websocket without ROS.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import Callable
from typing import Any

from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.http11 import Request, Response

from roslibpy_lite import Backoff


def fast_backoff() -> Backoff:
    """Reconnect delays small enough for tests (no jitter, 10 ms doubling to 50 ms)."""
    return Backoff(0.01, 0.05, jitter=0.0)


class ScriptedPeer:
    """A websocket server on 127.0.0.1 speaking JSON ops under the test's control."""

    def __init__(self) -> None:
        self.server: Server | None = None
        self.port = 0
        self.conns: list[ServerConnection] = []
        self.received: list[dict[str, Any]] = []
        self._changed = asyncio.Condition()
        self.auto: dict[str, Callable[[dict[str, Any]], dict[str, Any] | None]] = {}
        self.answer_headers: dict[str, str] = {}  # added to every handshake's answer

    @property
    def url(self) -> str:
        """The URL clients connect to."""
        return f"ws://127.0.0.1:{self.port}"

    async def start(self) -> ScriptedPeer:
        """Listen (on the same port as before after a :meth:`stop`)."""
        self.server = await serve(self._handle, "127.0.0.1", self.port,
                                  process_response=self._respond)
        self.port = self.server.sockets[0].getsockname()[1]
        return self

    def _respond(self, conn: ServerConnection, request: Request, response: Response) -> None:
        for name, value in self.answer_headers.items():
            response.headers[name] = value

    async def _handle(self, conn: ServerConnection) -> None:
        async with self._changed:
            self.conns.append(conn)
            self._changed.notify_all()
        try:
            async for frame in conn:
                op = json.loads(frame)
                answer = self.auto.get(op.get("op", ""))
                reply = answer(op) if answer is not None else None
                if reply is not None:
                    await conn.send(json.dumps(reply))
                async with self._changed:
                    self.received.append(op)
                    self._changed.notify_all()
        except Exception:
            pass

    async def wait_connections(self, n: int, timeout: float = 10.0) -> ServerConnection:
        """Wait until ``n`` connections were accepted in all; returns the latest."""
        async with asyncio.timeout(timeout), self._changed:
            await self._changed.wait_for(lambda: len(self.conns) >= n)
        return self.conns[-1]

    async def expect(self, timeout: float = 10.0, start: int = 0, **fields: Any) -> dict[str, Any]:
        """Wait for an op the client sent (from index ``start`` on) whose fields match."""

        def find() -> dict[str, Any] | None:
            for op in self.received[start:]:
                if all(op.get(k) == v for k, v in fields.items()):
                    return op
            return None

        async with asyncio.timeout(timeout), self._changed:
            await self._changed.wait_for(lambda: find() is not None)
        found = find()
        assert found is not None
        return found

    def count(self, start: int = 0, **fields: Any) -> int:
        """How many received ops (from ``start`` on) match ``fields``."""
        return sum(
            all(op.get(k) == v for k, v in fields.items()) for op in self.received[start:]
        )

    async def send(self, op: dict[str, Any] | str | bytes) -> None:
        """Send one op (a dict as JSON text; str/bytes as given) on the latest connection."""
        frame = json.dumps(op) if isinstance(op, dict) else op
        await self.conns[-1].send(frame)

    async def drop(self) -> None:
        """Close the latest connection abruptly (no close handshake)."""
        conn = self.conns[-1]
        conn.transport.abort()
        await conn.wait_closed()

    async def stop(self) -> None:
        """Stop listening and close every connection."""
        if self.server is not None:
            self.server.close()
            await self.server.wait_closed()
            self.server = None
