"""Sessions that survive a dropped link with --workers 2: the kernel hands each reconnect to
either worker, and the one that does not keep the session forwards it to the one that does
(bridge_server/front/forward.py), over ws:// and over wss:// with a token."""

from __future__ import annotations

import asyncio
import json
import os
import ssl
import urllib.request
from collections.abc import Iterator
from functools import partial
from typing import Any

import psutil
import pytest
from std_msgs.msg import Int32
from websockets.asyncio.client import ClientConnection
from websockets.asyncio.client import connect as ws_connect

import roslibpy_lite
from bench.linkproxy import LinkProxy
from rosbridge_core.protocol.ops import RECEIVED_HEADER, SESSION_HEADER
from roslibpy_lite.api import ConnectionState
from roslibpy_lite.transports.websocket import WebSocketTransport
from tests.bridge.support import wait_subscribers
from tests.helpers import BridgeProcess, async_wait_until
from tests.security.support import AuthFile, Certs, make_auth_file, make_certs

FENCE = -1
"""The number published after the last one of a test."""


class Workers:
    """A --workers 2 bridge (wss:// with tokens, or ws://) and how to connect to it."""

    def __init__(self, tls: bool, tmp: Any) -> None:
        self.certs: Certs | None = make_certs(tmp) if tls else None
        self.auth: AuthFile | None = make_auth_file(tmp) if tls else None
        args = ["--workers", "2", "--session-keep", "60"]
        if self.certs is not None and self.auth is not None:
            args += ["--certfile", str(self.certs.server), "--auth-file", str(self.auth.path)]
        self.bridge = BridgeProcess(args=args).start()

    def url(self, port: int) -> str:
        """The URL of ``port`` on 127.0.0.1 (the bridge's, or a proxy's in front of it)."""
        return f"{'wss' if self.certs else 'ws'}://127.0.0.1:{port}"

    def options(self) -> dict[str, Any]:
        """The TLS context and token a client needs here."""
        if self.certs is None or self.auth is None:
            return {}
        return {"ssl": self.certs.context(), "token": self.auth.tokens["tester"]}

    def tls_context(self) -> ssl.SSLContext | None:
        """The client TLS context (None for ws://)."""
        return None if self.certs is None else self.certs.context()

    def headers(self, role: str = "tester") -> dict[str, str]:
        """The raw handshake's credentials."""
        return {} if self.auth is None else {"Authorization": f"Bearer {self.auth.tokens[role]}"}

    async def status(self) -> dict[str, Any]:
        """The whole bridge's /status.json (every worker's, merged), seen as admin."""
        scheme = "https" if self.certs else "http"
        request = urllib.request.Request(
            f"{scheme}://127.0.0.1:{self.bridge.port}/status.json", headers=self.headers("admin"))

        def get() -> dict[str, Any]:
            with urllib.request.urlopen(request, context=self.tls_context(), timeout=10) as r:
                data: dict[str, Any] = json.load(r)
                return data

        return await asyncio.to_thread(get)

    async def forwarded(self) -> int:
        """How many resumes the workers forwarded so far."""
        return int((await self.status())["sessions_forwarded"])


@pytest.fixture(scope="module", params=["ws", "wss"])
def workers(request: pytest.FixtureRequest,
            tmp_path_factory: pytest.TempPathFactory) -> Iterator[Workers]:
    """One --workers 2 bridge per scheme for this module."""
    made = Workers(request.param == "wss", tmp_path_factory.mktemp("workers"))
    yield made
    made.bridge.stop()


async def test_every_reconnect_resumes_whichever_worker_takes_it(
    workers: Workers, ros_node: Any, topic: str
) -> None:
    """A subscriber whose link is cut again and again (at least 10 times, and until some
    reconnects landed on each worker) gets its session back every time, the same token,
    and every number ROS published, meanwhile too, exactly once and in order (up to a fence
    published after the last: no copy comes after it)."""
    bridge = workers.bridge
    ros_pub = ros_node.create_publisher(Int32, topic, 1000)
    seen = await workers.forwarded()
    kinds = {"direct": 0, "forwarded": 0}
    with LinkProxy(("127.0.0.1", bridge.port)) as proxy:
        async with roslibpy_lite.connect(workers.url(proxy.port), **workers.options()) as ros:
            ros.stable_after = 0.0  # each quick cut is a fresh reconnect, not a growing backoff
            transport = ros._transport
            assert isinstance(transport, WebSocketTransport) and transport.session is not None
            token = transport.session.token
            assert token is not None
            sub = await ros.subscribe(topic, "std_msgs/msg/Int32", queue_length=1000,
                                      buffer_size=1000)
            await wait_subscribers(ros_pub)
            published = 0
            cuts = 0

            def publish(n: int) -> None:
                nonlocal published
                for _ in range(n):
                    ros_pub.publish(Int32(data=published))
                    published += 1

            def opened(connects: int) -> bool:
                return ros.connects == connects and ros.state is ConnectionState.CONNECTED

            # until both kinds happened: the odds of 40 landing on one worker are 2**-40
            while cuts < 10 or not all(kinds.values()):
                assert cuts < 40, f"{cuts} reconnects: {kinds}"
                publish(5)
                proxy.cut()
                cuts += 1
                publish(5)  # while the link is down: kept by the session for the client
                await async_wait_until(partial(opened, cuts + 1), 20, f"reconnect {cuts}")
                assert transport.session.token == token, f"reconnect {cuts}: a new session"
                assert transport.session.resumes == cuts
                now = await workers.forwarded()
                kinds["forwarded" if now > seen else "direct"] += 1
                seen = now
            publish(5)
            # A fence after the last number: one ordered stream, so every number and every
            # copy the resumes sent again comes before it, and nothing after it.
            ros_pub.publish(Int32(data=FENCE))
            got = []
            while (data := (await sub.get(timeout=10))["data"]) != FENCE:
                got.append(data)
            assert sub.pending == 0
    assert got == list(range(published))
    assert sub.dropped == 0 and transport.session.lost == 0


async def test_a_token_naming_a_missing_worker_gets_a_new_session(workers: Workers) -> None:
    """A resume whose token names a worker that is not there (as one restarting is not)
    gets a new session from the worker it reached, promptly: no received count, a new
    token naming that worker."""
    made_up = "w7.AAAAAAAAAAAAAAAAAAAAAA"
    async with asyncio.timeout(5):
        ws = await ws_connect(workers.url(workers.bridge.port), ssl=workers.tls_context(),
                              additional_headers={SESSION_HEADER: made_up, RECEIVED_HEADER: "0",
                                                  **workers.headers()})
    try:
        assert ws.response is not None
        answer = ws.response.headers
        assert RECEIVED_HEADER not in answer
        assert answer[SESSION_HEADER] != made_up
        assert answer[SESSION_HEADER].startswith(f"w{answer['X-Bridge-Worker']}.")
    finally:
        await ws.close()
    workers.bridge.wait_for_line("names worker 7, which cannot be reached")


async def test_a_worker_that_closes_unanswered_leaves_the_resume_served_here(
    workers: Workers,
) -> None:
    """A forwarded resume that the other end closes without an answer (a worker killed while
    the request was on its way) gets a new session from the worker it reached."""
    assert workers.bridge.proc is not None
    supervisor = psutil.Process(workers.bridge.proc.pid)
    argv = supervisor.children()[0].cmdline()
    directory = argv[argv.index("--worker-dir") + 1]
    took: list[bytes] = []

    async def hang_up(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        took.append(await reader.readuntil(b"\r\n\r\n"))
        writer.close()

    server = await asyncio.start_unix_server(hang_up, os.path.join(directory, "forward-8.sock"))
    try:
        async with asyncio.timeout(5):
            ws = await ws_connect(workers.url(workers.bridge.port), ssl=workers.tls_context(),
                                  additional_headers={SESSION_HEADER: "w8.AAAAAAAAAAAAAAAAAAAAAA",
                                                      RECEIVED_HEADER: "0", **workers.headers()})
        assert ws.response is not None
        answer = ws.response.headers
        assert RECEIVED_HEADER not in answer
        assert answer[SESSION_HEADER].startswith(f"w{answer['X-Bridge-Worker']}.")
        await ws.close()
    finally:
        server.close()
        os.unlink(os.path.join(directory, "forward-8.sock"))
    assert len(took) == 1 and b"\r\nX-Bridge-Forwarded-For: 127.0.0.1:" in took[0]


async def test_a_forged_forwarding_header_is_replaced(workers: Workers) -> None:
    """A client that sends the workers' own X-Bridge-Forwarded-For header gains nothing: a
    direct connection is logged with its socket's address, and a forwarded one with the
    address the forwarding worker saw (its copy of the header replaced), never the forged
    one."""
    forged = {"X-Bridge-Forwarded-For": "10.9.8.7:1", **workers.headers()}
    url = workers.url(workers.bridge.port)

    async def open_(session: str) -> ClientConnection:
        extra = {SESSION_HEADER: session} | ({} if session == "new" else {RECEIVED_HEADER: "0"})
        ws = await ws_connect(url, ssl=workers.tls_context(), additional_headers=forged | extra)
        assert ws.response is not None
        return ws

    ws = await open_("new")
    assert ws.response is not None
    token = ws.response.headers[SESSION_HEADER]
    seen = await workers.forwarded()
    for _ in range(40):  # until one resume was forwarded (the odds of none: 2**-40)
        ws.transport.abort()
        ws = await open_(token)
        assert ws.response is not None and ws.response.headers[SESSION_HEADER] == token
        if await workers.forwarded() > seen:
            break
    else:
        raise AssertionError("no resume was forwarded in 40")
    port = ws.local_address[1]
    await ws.close()
    workers.bridge.wait_for_line(rf"\[w\d\] .*forwarded a session resume from 127\.0\.0\.1:{port} ")
    workers.bridge.wait_for_line(rf"reconnected from 127\.0\.0\.1:{port} and resumed")
    assert not any("10.9.8.7" in line for line in workers.bridge.lines)


async def test_a_resume_of_a_killed_workers_session_gets_a_new_session(
    workers: Workers,
) -> None:
    """The worker that keeps a session is killed (the supervisor restarts it, with none of its
    sessions): once it is gone, the client's resume gets a new session within 5 s, whichever
    worker takes it and whether the restarted one listens yet. Last in the module: it kills
    a worker."""
    import signal

    headers = workers.headers()
    url = workers.url(workers.bridge.port)
    ws = await ws_connect(url, ssl=workers.tls_context(),
                          additional_headers={SESSION_HEADER: "new", **headers})
    assert ws.response is not None
    token = ws.response.headers[SESSION_HEADER]
    pids = {w["index"]: w["pid"] for w in (await workers.status())["workers"]}
    dying = psutil.Process(pids[int(token[1])])
    os.kill(dying.pid, signal.SIGKILL)
    # until then the kernel may still hand a connection to its socket, which is then reset
    await asyncio.to_thread(dying.wait, 10)
    async with asyncio.timeout(5):
        again = await ws_connect(url, ssl=workers.tls_context(), additional_headers={
            SESSION_HEADER: token, RECEIVED_HEADER: "0", **headers})
    assert again.response is not None
    assert again.response.headers[SESSION_HEADER] != token
    assert RECEIVED_HEADER not in again.response.headers
    await again.close()
    ws.transport.abort()
