"""Faults and probes of issue 26 on a relay: without its router, losing it, tokens in logs.

- A relay whose Zenoh router is not up yet listens anyway: a client is answered 503 naming
  why (and ``/readyz`` too), and once the router comes the relay serves.
- A relay whose router goes away tells the robot's clients (a warning status), and when the
  router is back, that the robot is back (info), and messages flow again.
- A relay run with tokens at DEBUG: good and wrong tokens in the query, the header, the auth
  op and plain-HTTP requests, a token of a role for robot1 asking for robot2; no part of any
  token is in its log or in the error texts clients get.
"""

from __future__ import annotations

import asyncio
import json
import logging
import re
import sys
from pathlib import Path
from typing import Any

import pytest
from std_msgs.msg import String
from websockets.exceptions import ConnectionClosed, InvalidStatus

import roslibpy_lite
from bridge_server.front.server import BridgeConfig
from bridge_server.zenoh.link import ZenohOptions
from bridge_server.zenoh.relay import Relay
from tests.helpers import WireClient, open_wire, ros_env
from tests.ops.support import aget
from tests.relay.procs import Proc
from tests.relay.support import (
    ROBOT,
    ROBOT1_VIEWER,
    free_port,
    robot_reachable,
    start_relay,
    start_robot,
    tier,
    until,
)

pytestmark = pytest.mark.timeout(120)


async def _hears(wire: WireClient, pub: Any, topic: str, timeout: float = 30.0) -> None:
    """Publish from rclpy until ``wire`` hears ``topic`` (discovery and links have no event
    here)."""
    deadline = asyncio.get_running_loop().time() + timeout
    while True:
        pub.publish(String(data="hello"))
        try:
            await wire.expect(op="publish", topic=topic, timeout=0.3)
            return
        except AssertionError:
            assert asyncio.get_running_loop().time() < deadline, f"never heard {topic}"


async def test_a_relay_before_its_router_answers_503_then_serves(ros_node: Any, topic: str
                                                                 ) -> None:
    """A relay dialing a router that is not up: it listens, refuses a client with 503 naming
    the router it waits for, /readyz 503; the router comes, and the relay serves the robot."""
    router = f"tcp/127.0.0.1:{free_port()}"
    relay = Relay(BridgeConfig(port=0, node_name="relay"), ZenohOptions(connect=[router]))
    await relay.listen()
    joining = asyncio.ensure_future(relay.join())
    hub = robot = exporter = None
    try:
        url = f"ws://127.0.0.1:{relay.port}/{ROBOT}"
        with pytest.raises(InvalidStatus) as refused:
            await open_wire(url)
        response = refused.value.response
        assert response.status_code == 503 and response.headers["Retry-After"] == "1"
        assert f"has not reached its Zenoh router yet ({router})" in response.body.decode()
        code, _, body = await aget(f"http://127.0.0.1:{relay.port}/readyz")
        assert code == 503 and router.encode() in body
        code, _, body = await aget(f"http://127.0.0.1:{relay.port}/status.json")
        assert code == 200 and json.loads(body)["refused"] == {"no_router": 1}, body
        assert not joining.done()

        hub = await start_relay(listen=router)
        robot, exporter = await start_robot(router)
        await asyncio.wait_for(joining, 30)
        await robot_reachable(relay)
        assert (await aget(f"http://127.0.0.1:{relay.port}/readyz"))[0] == 200
        wire = await open_wire(url)
        try:
            await wire.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String"})
            await _hears(wire, ros_node.create_publisher(String, topic, 10), topic)
        finally:
            await wire.close()
    finally:
        joining.cancel()
        await relay.close()
        if hub is not None:
            await hub.close()
        if exporter is not None and robot is not None:
            await exporter.close()
            await robot.close()


async def test_the_relay_command_waits_for_its_router_while_listening() -> None:
    """``roslibpy-lite-relay --zenoh-connect`` to a router that is not up: it says it accepts
    and joins, /readyz is 503 naming the router; the router comes and it logs that it is
    listening (serving), /readyz 200; SIGTERM ends it cleanly."""
    router = f"tcp/127.0.0.1:{free_port()}"
    proc = Proc([sys.executable, "-m", "bridge_server.zenoh.relay", "--port", "0",
                 "--zenoh-connect", router], ros_env())
    hub = None
    try:
        port = int(proc.wait_for(re.compile(r"accepting on ws://127\.0\.0\.1:(\d+), joining "
                                            "Zenoh")).group(1))
        code, _, body = await aget(f"http://127.0.0.1:{port}/readyz")
        assert code == 503 and router.encode() in body, body
        assert not [line for line in proc.lines if "relay listening" in line]
        hub = await start_relay(listen=router)
        await asyncio.to_thread(proc.wait_for, re.compile(r"relay listening on ws://"))
        assert (await aget(f"http://127.0.0.1:{port}/readyz"))[0] == 200
    finally:
        proc.stop()
        if hub is not None:
            await hub.close()
    assert proc.proc.returncode == 0, "\n".join(proc.lines)


async def test_a_relay_that_loses_its_router_tells_its_clients(
        ros_node: Any, topic: str, caplog: pytest.LogCaptureFixture) -> None:
    """The router (another relay) dies: the clients of a relay that was its client are told
    the robot went away; the router comes back on its address, and they are told the robot
    is back and hear it again, on the same connection. A raw client is told whatever status
    level it left (rosbridge's default, error); ours logs the first at WARNING and the
    second at INFO, and gives both to on_status."""
    router = f"tcp/127.0.0.1:{free_port()}"
    hub = await start_relay(listen=router)
    robot, exporter = await start_robot(router)
    relay = await start_relay(router=router)
    pub = ros_node.create_publisher(String, topic, 10)
    caplog.set_level(logging.INFO, logger="roslibpy_lite.client")
    try:
        await robot_reachable(relay)
        url = f"ws://127.0.0.1:{relay.port}/{ROBOT}"
        wire = await open_wire(url)
        ours = await roslibpy_lite.connect(url)
        heard: list[tuple[str, str]] = []
        ours.on_status(lambda op: heard.append((op.level, op.msg)))
        try:
            await wire.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String"})
            await _hears(wire, pub, topic)
            await hub.close()
            gone = await wire.expect(op="status", level="warning", timeout=40)
            assert ROBOT in gone["msg"] and "went away" in gone["msg"], gone
            hub = await start_relay(listen=router)
            back = await wire.expect(op="status", level="info", timeout=60)
            assert ROBOT in back["msg"] and "back" in back["msg"], back
            wire.backlog.clear()
            await _hears(wire, pub, topic)
            await until(lambda: len(heard) >= 2, "our client to hear both")
            assert [level for level, _ in heard] == ["warning", "info"], heard
            said = [(r.levelno, r.getMessage()) for r in caplog.records
                    if r.name == "roslibpy_lite.client" and "bridge status" in r.getMessage()]
            assert [level for level, _ in said] == [logging.WARNING, logging.INFO], said
            assert "went away" in said[0][1] and "is back" in said[1][1]
        finally:
            await wire.close()
            await ours.close()
    finally:
        await relay.close()
        await hub.close()
        await exporter.close()
        await robot.close()


WRONG = "Wq7zXk2Vb9Lr4Tn8Jd1Hs6"  # random-looking: no 6 characters of it occur by chance


async def test_tokens_never_reach_a_relays_log_or_its_answers(tmp_path: Path) -> None:
    """A relay process at DEBUG with an auth file: the good token in the query, the header
    and the auth op, a wrong one in each, both on plain-HTTP routes, and the good one asking
    for robot2 (403): no 6 characters of either token are in its log (as text or hex), nor
    in any answer a client got."""
    from websockets.asyncio.client import connect

    from rosbridge_core.security.auth import hash_token, new_token

    good = new_token()
    auth = tmp_path / "auth.toml"
    auth.write_text(ROBOT1_VIEWER + f'\n[principals.viewer]\nrole = "robot1_viewer"\n'
                    f'token_hash = "{hash_token(good)}"\n')
    router = f"tcp/127.0.0.1:{free_port()}"
    proc = Proc([sys.executable, "-m", "bridge_server.zenoh.relay", "--port", "0",
                 "--auth-file", str(auth), "--log-level", "DEBUG", "--zenoh-listen", router],
                ros_env())
    robots = []
    answers: list[str] = []
    try:
        port = int(proc.wait_for(re.compile(r"relay listening on ws://127\.0\.0\.1:(\d+)"))
                   .group(1))
        robots = [await start_robot(router, robot=name) for name in ("robot1", "robot2")]
        base = f"ws://127.0.0.1:{port}"

        async def refused(url: str, **kw: Any) -> None:
            with pytest.raises(InvalidStatus) as exc:
                await connect(url, open_timeout=10, **kw)
            answers.append(exc.value.response.body.decode())

        deadline = asyncio.get_running_loop().time() + 30
        while True:  # until robot1's liveliness reached the relay: 404 till then
            try:
                wire = await open_wire(f"{base}/robot1?token={good}")
                break
            except InvalidStatus as exc:
                assert exc.response.status_code == 404, exc.response.body
                assert asyncio.get_running_loop().time() < deadline, "robot1 never served"
                await asyncio.sleep(0.1)
        await wire.close()
        async with connect(f"{base}/robot1",
                           additional_headers={"Authorization": f"Bearer {good}"}):
            pass
        wire = await open_wire(f"{base}/robot1")
        await wire.send({"op": "auth", "mac": good})
        await wire.send({"op": "call_service", "service": "/rosapi/topics", "id": "t"})
        answers.append(str(await wire.expect(op="service_response", id="t")))
        await wire.close()
        await refused(f"{base}/robot1?token={WRONG}")
        await refused(f"{base}/robot1", additional_headers={"Authorization": f"Bearer {WRONG}"})
        await refused(f"{base}/robot2?token={good}")
        wire = await open_wire(f"{base}/robot1")
        await wire.send({"op": "auth", "mac": WRONG})
        with pytest.raises(ConnectionClosed):
            while True:
                answers.append(str(await wire.recv()))
        answers.append(str(wire.ws.close_reason))
        http = f"http://127.0.0.1:{port}"
        for path in ("/status.json", "/metrics", "/robot1/status.json", "/robot2/metrics"):
            for token in (good, WRONG):
                code, headers, body = await aget(f"{http}{path}?token={token}")
                answers.append(f"{code} {headers} {body.decode()}")
        proc.wait_for(re.compile(r"plain-HTTP request .* wrong token"))
        proc.wait_for(re.compile(r"asking for robot robot2: not among its robots"))
    finally:
        proc.stop()
        for bridge, exporter in robots:
            await exporter.close()
            await bridge.close()
    log = "\n".join(proc.lines)
    assert "authenticated as viewer" in log
    flat = log.replace(" ", "")
    for token in (good, WRONG):
        for i in range(len(token) - 5):  # no part of it, as text or as hex
            part = token[i:i + 6]
            assert part not in log and part.encode().hex() not in flat, part
            assert not [a for a in answers if part in a], part


async def test_a_dropped_client_resumes_its_session_on_the_relay(ros_node: Any, topic: str
                                                                 ) -> None:
    """Our client's link to a relay is cut and stays down a moment: the relay keeps its
    session, the client resumes it (the session token in the relay's handshake answer) and
    gets every message the robot published meanwhile, once and in order."""
    from bench.linkproxy import LinkProxy
    from roslibpy_lite import ConnectionState, connect
    from tests.client.support import fast_backoff

    pub = ros_node.create_publisher(String, topic, 100)
    async with tier() as t:
        with LinkProxy(("127.0.0.1", t.relay.port)) as link:
            async with connect(f"ws://127.0.0.1:{link.port}/{ROBOT}",
                               backoff=fast_backoff()) as ros:
                got: list[int] = []
                ros.subscribe(topic, "std_msgs/msg/String", queue_length=100,
                              callback=lambda m: got.append(int(m["data"])))
                n = 0
                deadline = asyncio.get_running_loop().time() + 30
                while not got:  # until the relay's subscription hears the robot
                    n += 1
                    pub.publish(String(data=str(n)))
                    await asyncio.sleep(0.02)
                    assert asyncio.get_running_loop().time() < deadline, "never heard it"
                link.refuse()
                link.cut()
                for _ in range(20):  # published while the client is away
                    n += 1
                    pub.publish(String(data=str(n)))
                    await asyncio.sleep(0.02)
                bridge = t.relay.robots[ROBOT]
                await until(lambda: [s.parked for s in bridge.sessions] == [True],
                            "the relay to keep the session")
                link.restore()
                last = n
                deadline = asyncio.get_running_loop().time() + 30
                while not (ros.state is ConnectionState.CONNECTED and got[-1] >= last):
                    assert asyncio.get_running_loop().time() < deadline, got
                    await asyncio.sleep(0.02)
                assert bridge.resumable.resumed == 1
                assert got == list(range(got[0], last + 1)), got


async def test_the_relay_leaves_pings_to_its_sessions_keepalive() -> None:
    """Like the bridge, the relay turns websockets' own ping timeout off where its sessions
    watch their links (keepalive.py pings a silent client first; a pong late behind a big
    frame, or after a stall of the relay's own, drops nobody)."""
    from rosbridge_core.protocol import keepalive

    async with tier() as t:
        wire = await open_wire(t.url())
        try:
            await wire.send({"op": "call_service", "service": "/rosapi/topics", "id": "up"})
            await wire.expect(op="service_response", id="up")
            server = t.relay._server
            assert server is not None
            (connection,) = server.connections
            expected = None if keepalive.supported_here() else t.relay.config.keepalive_interval
            assert connection.ping_interval == expected
        finally:
            await wire.close()


async def test_a_relay_that_cannot_join_zenoh_closes_what_it_opened() -> None:
    """A relay whose Zenoh listen address is taken fails to start naming the address, and its
    websocket port (opened first) is closed again, not left bound in the process (in CI it
    was, and the next test failed on its ResourceWarning)."""
    import socket

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        address = f"127.0.0.1:{taken.getsockname()[1]}"
        relay = Relay(BridgeConfig(port=0, node_name="relay"),
                      ZenohOptions(listen=[f"tcp/{address}"]))
        with pytest.raises(Exception, match=re.escape(address)):
            await relay.start()
    assert relay._server is not None and not relay._server.sockets
