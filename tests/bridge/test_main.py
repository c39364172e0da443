"""``python -m bridge_server``: start-up, logging, limits and clean exit on signals."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed

from tests.bridge.support import ros_future, serve_set_bool
from tests.helpers import ROOT, ros_env, roundtrip


def test_help_lists_options() -> None:
    """``--help`` exits 0 and documents the main options."""
    out = subprocess.run(
        [sys.executable, "-m", "bridge_server", "--help"],
        cwd=ROOT, env=ros_env(), capture_output=True, text=True, timeout=60, check=True,
    ).stdout
    for option in ("--host", "--port", "--max-message-size", "--send-queue", "--log-level",
                   "--publisher-grace"):
        assert option in out


async def test_logs_connect_and_disconnect(make_bridge: Any, ws_connect: Any) -> None:
    """Each connection and disconnection is logged with the peer address and session id."""
    bridge = make_bridge()
    start = len(bridge.lines)
    ws = await ws_connect(bridge.url)
    await roundtrip(ws)
    line = bridge.wait_for_line(r"client \d+ connected from 127\.0\.0\.1:\d+", start=start)
    sid = line.split("client ")[1].split()[0]
    await ws.close()
    bridge.wait_for_line(rf"client {sid} \(127\.0\.0\.1:\d+\) disconnected", start=start)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
async def test_signal_exits_cleanly(make_bridge: Any, ws_connect: Any, sig: int) -> None:
    """SIGINT and SIGTERM stop the bridge promptly with exit code 0, even with busy clients."""
    bridge = make_bridge()
    ws = await ws_connect(bridge.url)
    await ws.send({"op": "subscribe", "topic": "/exit_test", "type": "std_msgs/String"})
    await ws.send({"op": "advertise", "topic": "/exit_test", "type": "std_msgs/String"})
    await ws.send({"op": "advertise_service", "service": "/exit_srv", "type": "std_srvs/SetBool"})
    await roundtrip(ws)
    started = time.monotonic()
    code = bridge.stop(sig, timeout=10)
    took = time.monotonic() - started
    assert code == 0, bridge.log()
    print(f"exit after {sig!r} took {took:.3f} s")  # measured, not asserted (see bench/)
    with pytest.raises(ConnectionClosed):
        await ws.recv(timeout=5)


async def test_inbound_size_limit(make_bridge: Any) -> None:
    """A frame over --max-message-size closes that connection with code 1009, others live on."""
    bridge = make_bridge("--max-message-size", "2000")
    async with connect(bridge.url) as big, connect(bridge.url) as other:
        await big.send(json.dumps({"op": "publish", "topic": "/x", "msg": {"data": "y" * 5000}}))
        with pytest.raises(ConnectionClosed) as info:
            await big.recv()
        assert info.value.rcvd is not None and info.value.rcvd.code == 1009
        await other.send(json.dumps({"op": "call_service", "id": "v",
                                     "service": "/rosapi/get_ros_version"}))
        reply = json.loads(await other.recv())
        assert reply["result"] is True


async def test_publisher_released_after_disconnect(make_bridge: Any, ros_node: Any, topic: str) -> None:
    """A disconnected client's publisher is removed after the grace period."""
    from std_msgs.msg import String

    from tests.bridge.support import wait_publishers
    from tests.helpers import async_wait_until

    bridge = make_bridge("--publisher-grace", "0.2")
    sub = ros_node.create_subscription(String, topic, lambda m: None, 10)
    async with connect(bridge.url) as ws:
        await ws.send(json.dumps({"op": "advertise", "topic": topic, "type": "std_msgs/String"}))
        await wait_publishers(sub)
    await async_wait_until(lambda: sub.get_publisher_count() == 0, what="publisher released")


async def test_fragments_bounded_by_max_message_size(make_bridge: Any) -> None:
    """Fragments cannot build an op larger than --max-message-size: the sender is told."""
    bridge = make_bridge("--max-message-size", "2000")
    async with connect(bridge.url) as ws:
        piece = "x" * 500
        for num in range(6):
            await ws.send(json.dumps({"op": "fragment", "id": "big", "data": piece,
                                      "num": num, "total": 10}))
        status = json.loads(await ws.recv())
        assert status["op"] == "status" and status["level"] == "error"
        assert status["id"] == "big" and "2000" in status["msg"]
        await ws.send(json.dumps({"op": "call_service", "id": "v",
                                  "service": "/rosapi/get_ros_version"}))
        assert json.loads(await ws.recv())["result"] is True


@pytest.mark.parametrize(("kind", "runs"), [("auto", "uvloop"), ("uvloop", "uvloop"),
                                            ("asyncio", "asyncio")])
async def test_the_bridge_runs_on_the_event_loop_asked_for(
    kind: str, runs: str, make_bridge: Any, ws_connect: Any, ros_node: Any, topic: str
) -> None:
    """``--event-loop``: the bridge says which loop it runs (auto: uvloop, which the bridge
    extra installs), and a ROS caller gets a client's answer through it."""
    from std_srvs.srv import SetBool

    bridge = make_bridge("--event-loop", kind)
    assert bridge.wait_for_line(r"event loop: ").endswith(f"event loop: {runs}")
    ws = await ws_connect(bridge.url)
    client = await serve_set_bool(ws, ros_node, topic)
    future = client.call_async(SetBool.Request(data=True))
    request = await ws.expect(op="call_service", service=topic)
    await ws.send({"op": "service_response", "service": topic, "id": request["id"],
                   "result": True, "values": {"success": True, "message": runs}})
    assert (await ros_future(future)).message == runs


def test_uvloop_asked_for_where_it_cannot_be_imported_is_refused(tmp_path: Path) -> None:
    """``--event-loop uvloop`` where uvloop does not import: the bridge does not start, and
    says why."""
    (tmp_path / "uvloop").mkdir()
    (tmp_path / "uvloop" / "__init__.py").write_text('raise ImportError("no uvloop here")\n')
    env = ros_env()
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(tmp_path), env.get("PYTHONPATH")]))
    out = subprocess.run(
        [sys.executable, "-m", "bridge_server", "--port", "0", "--event-loop", "uvloop"],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=60,
    )
    assert out.returncode == 1, out.stderr
    assert "--event-loop uvloop: uvloop cannot be imported (no uvloop here)" in out.stderr
