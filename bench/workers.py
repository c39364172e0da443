"""What the hop costs a session resumed on the wrong worker (``--scenario workers_resume``).

With ``--workers 2`` a resume that the kernel hands to the worker that does not keep the
session is forwarded to the one that does (``bridge_server/front/forward.py``): one more
process and a unix socket on the way, and over wss:// the forwarding worker ends TLS. Here a
raw client opens a resumable session, then drops its link and resumes again and again; after
each resume it times sequential call_service round trips to an rclpy SetBool service, and
the bridge's log says whether that connection was forwarded (the forwarding worker names
the client's address). The result puts the forwarded connections' round trips beside the
direct ones', over ws:// and wss://. Nothing here asserts anything about time.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from typing import Any

from websockets.asyncio.client import ClientConnection, connect

from bench.harness import Ctx, client_ssl, percentile, send_op
from bench.tls import make_certs

__all__ = ["workers_resume"]

SESSION = "X-Rosbridge-Session"
RECEIVED = "X-Rosbridge-Received"


class _Client:
    """A raw client of one resumable session: counts what it receives, answers calls."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.token = "new"
        self.received = 0  # frames of the session, session_ack excepted
        self.ws: ClientConnection | None = None
        self.reader: asyncio.Task[None] | None = None
        self.waiting: dict[str, asyncio.Future[dict[str, Any]]] = {}
        self.calls = 0

    async def open(self) -> bool:
        """(Re)connect; whether the session was resumed."""
        headers = {SESSION: self.token}
        if self.token != "new":
            headers[RECEIVED] = str(self.received)
        ws = await connect(self.url, additional_headers=headers, max_size=None,
                           compression=None, open_timeout=10, ssl=client_ssl(self.url))
        assert ws.response is not None
        resumed = RECEIVED in ws.response.headers
        token = ws.response.headers[SESSION]
        if self.token not in ("new", token):
            self.received = 0  # a new session: counts start again
        self.token, self.ws = token, ws
        self.reader = asyncio.create_task(self._read(ws))
        return resumed

    async def _read(self, ws: ClientConnection) -> None:
        with contextlib.suppress(Exception):
            async for frame in ws:
                op = json.loads(frame)
                if op.get("op") == "session_ack":
                    continue
                self.received += 1
                fut = self.waiting.pop(str(op.get("id")), None)
                if fut is not None and not fut.done():
                    fut.set_result(op)

    async def drop(self) -> None:
        """Lose the link without a word (as a dead one)."""
        assert self.ws is not None and self.reader is not None
        self.ws.transport.abort()
        with contextlib.suppress(asyncio.CancelledError):
            await self.reader

    async def call(self, service: str) -> dict[str, Any]:
        """One call_service round trip."""
        assert self.ws is not None
        self.calls += 1
        rid = f"c{self.calls}"
        fut: asyncio.Future[dict[str, Any]] = asyncio.get_running_loop().create_future()
        self.waiting[rid] = fut
        await send_op(self.ws, {"op": "call_service", "service": service, "id": rid,
                                "type": "std_srvs/srv/SetBool", "args": {"data": True}})
        return await asyncio.wait_for(fut, 25)


async def _one_scheme(ctx: Ctx, extra: list[str]) -> dict[str, Any]:
    """Forwarded against direct round trips on one --workers 2 bridge."""
    name = "/bench/srv"
    bridge = ctx.bridge()
    bridge.args += ["--workers", "2", *extra]
    await bridge.start()
    srv = await ctx.ros("serve", "--service", name, "--duration", "300").start()
    await srv.event("ready")
    client = _Client(bridge.url)
    lat: dict[str, list[float]] = {"direct": [], "forwarded": []}
    blocks = {"direct": 0, "forwarded": 0}
    not_resumed = 0
    per_block = 100 if ctx.quick else 300
    try:
        await client.open()
        deadline = time.monotonic() + 20
        while (await client.call(name)).get("result") is not True:  # discovery first
            if time.monotonic() > deadline:
                raise RuntimeError("the service never answered")
        for _ in range(40):
            if min(blocks.values()) >= 3:
                break
            await client.drop()
            if not await client.open():
                not_resumed += 1
            assert client.ws is not None
            here = f"from 127.0.0.1:{client.ws.local_address[1]} to worker"
            for _ in range(20):
                await client.call(name)  # warm up
            times = []
            for _ in range(per_block):
                t = time.perf_counter_ns()
                await client.call(name)
                times.append((time.perf_counter_ns() - t) / 1e6)
            # the forwarding worker logged this connection long before the calls ended
            kind = "forwarded" if any(here in line for line in bridge.lines) else "direct"
            blocks[kind] += 1
            lat[kind] += times
    finally:
        if client.ws is not None:
            await client.ws.close()
        await srv.close()
        await bridge.stop()
    out: dict[str, Any] = {"resumes_not_resumed": not_resumed, "blocks": blocks,
                           "calls_per_block": per_block}
    for kind, values in lat.items():
        out[kind] = {"p50_ms": round(percentile(values, 0.5), 3),
                     "p99_ms": round(percentile(values, 0.99), 3)}
    out["hop_p50_ms"] = round(out["forwarded"]["p50_ms"] - out["direct"]["p50_ms"], 3)
    return out


async def workers_resume(ctx: Ctx) -> dict[str, Any]:
    """Service round trips through a forwarded resumed connection against a direct one, over
    ws:// and wss://."""
    certfile = make_certs()
    return {
        "ws": await _one_scheme(ctx, []),
        "wss": await _one_scheme(ctx, ["--certfile", certfile]),
    }
