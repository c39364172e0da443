"""Resume paths beside the common one, on the wire against a real bridge: a token presented
by another principal, more kept sessions than --sessions-per-principal, and a resume past
--resume-frames (the client hears how many messages it missed)."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Any

from std_msgs.msg import Int32
from websockets.asyncio.client import ClientConnection
from websockets.asyncio.client import connect as ws_connect

from rosbridge_core.protocol.ops import RECEIVED_HEADER, SESSION_HEADER
from tests.bridge.support import wait_subscribers
from tests.helpers import BridgeProcess, WireClient, async_wait_until
from tests.ops.support import aget
from tests.security.support import make_auth_file


async def _open(bridge: BridgeProcess, token: str = "new", received: int | None = None,
                auth: str | None = None) -> ClientConnection:
    headers = {SESSION_HEADER: token}
    if received is not None:
        headers[RECEIVED_HEADER] = str(received)
    if auth is not None:
        headers["Authorization"] = f"Bearer {auth}"
    return await ws_connect(bridge.url, additional_headers=headers, max_size=None)


def _answer(ws: ClientConnection) -> tuple[str, str | None]:
    assert ws.response is not None
    return ws.response.headers[SESSION_HEADER], ws.response.headers.get(RECEIVED_HEADER)


async def _parked(bridge: BridgeProcess, n: int, token: str | None = None) -> None:
    """Wait until the status page (seen with ``token`` if given) lists ``n`` kept sessions."""
    url = f"http://127.0.0.1:{bridge.port}/status.json" + (f"?token={token}" if token else "")

    async def count() -> int:
        code, _, body = await aget(url)
        assert code == 200, body
        return sum(1 for c in json.loads(body)["clients"] if c["parked"])

    async with asyncio.timeout(10):
        while await count() != n:
            await asyncio.sleep(0.05)


async def test_another_principal_cannot_resume_a_session(tmp_path: Path, topic: str) -> None:
    """A session token presented with another principal's credentials gets a new session
    (no received count, a different token) and leaves the kept one alone: its own principal
    then resumes it."""
    auth = make_auth_file(tmp_path)
    bridge = BridgeProcess(args=["--auth-file", str(auth.path), "--session-keep", "60"]).start()
    try:
        ws = await _open(bridge, auth=auth.tokens["viewer"])
        token, _ = _answer(ws)
        ws.transport.abort()
        await _parked(bridge, 1, auth.tokens["admin"])
        other = await _open(bridge, token, 0, auth=auth.tokens["tester"])
        assert _answer(other)[0] != token and _answer(other)[1] is None
        await other.close()
        await _parked(bridge, 1, auth.tokens["admin"])  # still kept for its owner
        mine = await _open(bridge, token, 0, auth=auth.tokens["viewer"])
        assert _answer(mine) == (token, "0")
        await mine.close()
    finally:
        bridge.stop()


async def test_the_oldest_kept_session_goes_past_sessions_per_principal(
    make_bridge: Any, ros_node: Any, topic: str
) -> None:
    """With --sessions-per-principal 1 a second dropped session ends the first one kept
    (logged as such, its ROS subscription released); the second still resumes."""
    bridge = make_bridge("--session-keep", "60", "--sessions-per-principal", "1")
    pub = ros_node.create_publisher(Int32, topic, 10)
    first = await _open(bridge)
    first_token, _ = _answer(first)
    await WireClient(first).send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/Int32"})
    await wait_subscribers(pub)
    first.transport.abort()
    await _parked(bridge, 1)
    second = await _open(bridge)
    second_token, _ = _answer(second)
    second.transport.abort()
    await async_wait_until(
        lambda: any("too many kept sessions for its principal" in line for line in bridge.lines),
        10, "the first kept session to be ended")
    await _parked(bridge, 1)
    await async_wait_until(lambda: pub.get_subscription_count() == 0, 10,
                           "the ended session's subscription to go")
    again = await _open(bridge, first_token, 0)
    assert _answer(again)[0] != first_token  # ended: a new session
    await again.close()
    resumed = await _open(bridge, second_token, 0)
    assert _answer(resumed) == (second_token, "0")
    await resumed.close()


async def test_a_resume_past_resume_frames_says_how_many_were_missed(
    make_bridge: Any, ros_node: Any, topic: str
) -> None:
    """With --resume-frames 3 and a client that confirmed none of the ten messages it was
    written before its link dropped: resuming from 0 sends the last three again, after a
    warning that seven were no longer kept."""
    bridge = make_bridge("--session-keep", "60", "--resume-frames", "3")
    pub = ros_node.create_publisher(Int32, topic, 100)
    ws = await _open(bridge)
    token, _ = _answer(ws)
    wire = WireClient(ws)  # a raw peer: it sends no session_ack
    await wire.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/Int32",
                     "queue_length": 100})
    await wait_subscribers(pub)
    for i in range(10):
        pub.publish(Int32(data=i))
    assert [(await wire.expect(op="publish"))["msg"]["data"] for _ in range(10)] == list(
        range(10))
    ws.transport.abort()
    await _parked(bridge, 1)
    again = WireClient(await _open(bridge, token, 0))
    warning = await again.expect(op="status", level="warning")
    assert "7 messages sent while the link was down were no longer kept" in warning["msg"]
    got = [(await again.expect(op="publish"))["msg"]["data"] for _ in range(3)]
    assert got == [7, 8, 9]
    await again.close()
