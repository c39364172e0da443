"""Error paths that need a real socket or a real bridge: connecting, acks, late services."""

from __future__ import annotations

import asyncio
import logging
from typing import Any

import pytest
from websockets.asyncio.server import serve

import roslibpy_lite
from roslibpy_lite import ConnectError, UsageError
from roslibpy_lite.transports.base import ACKS_HEADER
from tests.client.support import ScriptedPeer

MULT = "mult_msgs/srv/MultFloats"


async def test_nothing_listening_says_what_was_tried_and_what_to_check(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """ConnectError names the URL, the attempts and what to check; retries are logged at INFO."""
    with caplog.at_level(logging.INFO, "roslibpy_lite.client"), \
            pytest.raises(ConnectError) as failed:
        await roslibpy_lite.connect("ws://127.0.0.1:1", open_timeout=1.0)
    text = str(failed.value)
    assert text.startswith("cannot connect to ws://127.0.0.1:1 (")
    assert "attempts in" in text and "ConnectionRefusedError" in text
    assert "check that a rosbridge server is running there" in text
    assert "cannot connect to ws://127.0.0.1:1 yet" in caplog.text


async def test_wss_to_a_plain_server_says_use_ws() -> None:
    """wss:// against a plain websocket server fails at once with a one-line hint to use ws://."""
    async with serve(lambda ws: ws.wait_closed(), "127.0.0.1", 0) as server:
        port = server.sockets[0].getsockname()[1]
        with pytest.raises(ConnectError, match=f"use ws://127.0.0.1:{port}") as failed:
            await roslibpy_lite.connect(f"wss://127.0.0.1:{port}", open_timeout=30)
    assert "(1 attempt in" in str(failed.value)
    assert "\n" not in str(failed.value)


async def test_unawaited_connect_says_did_you_forget_await() -> None:
    """Using connect()'s Connector as a client raises UsageError naming the fix."""
    connector = roslibpy_lite.connect("ws://127.0.0.1:1")
    with pytest.raises(UsageError, match="did you forget await") as failed:
        connector.advertise("/x", "std_msgs/msg/String")
    assert "ros = await roslibpy_lite.connect(url)" in str(failed.value)
    with pytest.raises(AttributeError):
        connector.no_such_thing  # noqa: B018


async def test_acks_are_negotiated(bridge: Any) -> None:
    """Our bridge announces acks in the handshake; a stock-like peer does not, and is not waited for."""
    async with roslibpy_lite.connect(bridge.url) as ros:
        assert ros._ws.acks
    peer = await ScriptedPeer().start()
    try:
        async with roslibpy_lite.connect(peer.url) as ros:
            assert not ros._ws.acks
            pub = await ros.advertise("/no_acks", "std_msgs/msg/String")
            assert pub.error is None
    finally:
        await peer.stop()


async def test_stock_clients_get_no_acks(ws_connect: Any, topic: str) -> None:
    """A client that did not ask for acks gets no info status for an accepted advertise."""
    wire = await ws_connect()
    await wire.send({"op": "advertise", "topic": topic, "type": "std_msgs/msg/String", "id": "a1"})
    await wire.send({"op": "call_service", "service": "/rosapi/get_time", "id": "c1"})
    first = await wire.recv()
    assert first["op"] == "service_response" and first["id"] == "c1"


async def test_ack_header_name() -> None:
    """The handshake header is the documented one."""
    assert ACKS_HEADER == "X-Rosbridge-Acks"


async def test_a_service_that_appears_late_is_found(bridge: Any, topic: str) -> None:
    """A typed call waits for a service that appears within the bridge's discovery window."""
    async with roslibpy_lite.connect(bridge.url) as caller, \
            roslibpy_lite.connect(bridge.url) as server:
        call = asyncio.ensure_future(
            caller.call_service(topic, MULT, {"x": 2.0, "y": 3.0}, timeout=20)
        )
        await asyncio.sleep(0.5)  # the condition under test: the server comes after the call
        assert not call.done()
        await server.advertise_service(topic, MULT, lambda req: {"result": req["x"] * req["y"]})
        assert await call == {"result": 6.0}


async def test_unawaited_publish_that_needed_waiting_says_so(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """A publish past max_pending that is never awaited logs 'did you forget await?' (still sent)."""
    peer = await ScriptedPeer().start()
    try:
        async with roslibpy_lite.connect(peer.url, max_pending=1) as ros:
            pub = await ros.advertise("/backpressure", "std_msgs/msg/Int32")
            with caplog.at_level(logging.ERROR, "roslibpy_lite.client"):
                for i in range(3):
                    pub.publish({"data": i})  # type: ignore[unused-coroutine]
            assert "never awaited: did you forget await?" in caplog.text
            await peer.expect(op="publish", msg={"data": 2})
    finally:
        await peer.stop()


async def test_concurrent_calls_to_a_missing_service_leave_no_task_errors(
    bridge: Any, topic: str
) -> None:
    """Typed calls racing on one missing service all fail cleanly; the bridge logs no stray errors."""
    async with roslibpy_lite.connect(bridge.url) as ros:
        calls = [ros.call_service(topic, MULT, {}, timeout=20) for _ in range(4)]
        results = await asyncio.gather(*calls, return_exceptions=True)
    assert all("does not exist" in str(r) for r in results), results
    assert not [line for line in bridge.lines if "never retrieved" in line]
