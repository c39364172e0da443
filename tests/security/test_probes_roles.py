"""The second security probe (issue 20): each way past the roles and limits, closed.

Each test checks the effect on the ROS side (a handler that did or did not run, a parameter
that did or did not change, a ROS subscription that went away), not only the status that
came back, and shows with an allowed principal that the same request does reach ROS.
"""

from __future__ import annotations

import asyncio
import json
import threading
from pathlib import Path
from typing import Any

import pytest
from std_msgs.msg import String
from std_srvs.srv import SetBool
from websockets.exceptions import ConnectionClosed

from tests.bridge.support import wait_subscribers
from tests.helpers import BridgeProcess, async_wait_until, open_wire, roundtrip
from tests.ops.support import aget
from tests.security.support import AuthFile, WatcherAuth, bridge_entities, wire

SETBOOL = "std_srvs/srv/SetBool"


def _recording_service(ros_node: Any, name: str) -> list[bool]:
    """An rclpy SetBool service that records each request it gets."""
    calls: list[bool] = []
    lock = threading.Lock()

    def serve(req: Any, resp: Any) -> Any:
        with lock:
            calls.append(req.data)
        resp.success = True
        resp.message = "rclpy"
        return resp

    ros_node.create_service(SetBool, name, serve)
    return calls


async def _refused(ws: Any, id: str, *words: str) -> str:
    status = await ws.expect(op="status", id=id)
    assert status["level"] == "error", status
    for w in words:
        assert w in status["msg"], (w, status["msg"])
    return str(status["msg"])


@pytest.mark.parametrize(
    ("hidden", "capability", "governing"),
    [("/probe/act/_action/cancel_goal", "send_action_goal", "/probe/act"),
     ("/probe/act/_action/send_goal", "send_action_goal", "/probe/act"),
     ("/probe/ctrl/set_parameters", "params", "/probe/ctrl:*")],
)
async def test_hidden_services_need_their_own_capability(
    connect_as: Any, ros_node: Any, hidden: str, capability: str, governing: str
) -> None:
    """An action's internal services and a node's parameter services, called as plain services
    under a call_service glob, are refused; the ROS handler never runs (it does for admin)."""
    calls = _recording_service(ros_node, hidden)
    prober = await connect_as("prober")
    await prober.send({"op": "call_service", "service": hidden, "type": SETBOOL,
                       "args": {"data": False}, "id": "c"})
    await _refused(prober, "c", "forbidden", "prober", capability, governing, hidden)
    reply = await prober.expect(op="service_response", id="c")
    assert reply["result"] is False
    admin = await connect_as("admin")
    await admin.send({"op": "call_service", "service": hidden, "type": SETBOOL,
                      "args": {"data": True}, "id": "a", "timeout": 30})
    assert (await admin.expect(op="service_response", id="a"))["result"] is True
    assert calls == [True]  # only the admin's call reached the service


@pytest.mark.parametrize(
    ("op", "name", "capability"),
    [("subscribe", "/probe/act/_action/status", "send_action_goal on /probe/act"),
     ("subscribe", "/probe/act/_action/feedback", "send_action_goal on /probe/act"),
     ("subscribe", "/parameter_events", "params on *:*"),
     ("advertise", "/probe/act/_action/feedback", "serve_action on /probe/act")],
)
async def test_action_topics_and_parameter_events_need_their_capability(
    connect_as: Any, auth_bridge: BridgeProcess, ros_node: Any, topic: str, op: str,
    name: str, capability: str
) -> None:
    """Subscribing to an action's feedback/status or to /parameter_events, or publishing an
    action's feedback, needs the capability that governs them: the bridge's node makes no
    such subscription or publisher (it does for admin)."""
    prober = await connect_as("prober")
    types = {"/parameter_events": "rcl_interfaces/msg/ParameterEvent",
             "/probe/act/_action/status": "action_msgs/msg/GoalStatusArray"}
    request = {"op": op, "topic": name, "type": types.get(name, "std_msgs/msg/String")}
    await prober.send({**request, "id": "x"})
    await _refused(prober, "x", "forbidden", capability)
    admin = await connect_as("admin")
    kind = "subscriptions" if op == "subscribe" else "publishers"
    assert name not in (await bridge_entities(ros_node, auth_bridge, admin, topic + "_a"))[kind]
    await admin.send({**request, "id": "y"})
    assert name in (await bridge_entities(ros_node, auth_bridge, admin, topic + "_b"))[kind]


async def test_nul_in_a_rosapi_parameter_name_is_refused(connect_as: Any, ros_node: Any) -> None:
    """set_param with a NUL in the name is refused and the parameter keeps its value; an
    allowed name (the role's '*_display' glob) does change."""
    from rclpy.parameter import Parameter

    ros_node.declare_parameter("speed_limit", 1.0)
    ros_node.declare_parameter("brightness_display", 0.5)
    node = ros_node.get_fully_qualified_name()
    prober = await connect_as("prober")
    for name, id in ((f"{node}:speed_limit\u0000_display", "nul"), (f"{node}:speed_limit\u0000", "end")):
        await prober.send({"op": "call_service", "service": "/rosapi/set_param", "id": id,
                           "args": {"name": name, "value": "9.0"}})
        await _refused(prober, id, "control character")
    await prober.send({"op": "call_service", "service": "/rosapi/set_param", "id": "ok",
                       "args": {"name": f"{node}:brightness_display", "value": "0.7"},
                       "timeout": 30})
    reply = await prober.expect(op="service_response", id="ok")
    assert reply["result"] is True, reply
    assert ros_node.get_parameter("brightness_display").value == pytest.approx(0.7)
    assert ros_node.get_parameter("speed_limit").get_parameter_value().double_value == 1.0
    assert ros_node.get_parameter("speed_limit").type_ == Parameter.Type.DOUBLE


async def test_deny_star_blocks_checks_that_take_no_name(auth_bridge: BridgeProcess, auth: AuthFile) -> None:
    """deny.introspection = ["*"] refuses the rosapi lists and the status routes."""
    blind = await wire(auth_bridge.url, auth.tokens["blind"])
    await blind.send({"op": "call_service", "service": "/rosapi/topics", "id": "t"})
    await _refused(blind, "t", "forbidden", "introspection")
    await blind.send({"op": "call_service", "service": "/rosapi/get_time", "id": "g"})
    await _refused(blind, "g", "forbidden", "introspection")
    code, _, _ = await aget(f"http://127.0.0.1:{auth_bridge.port}/status.json"
                            f"?token={auth.tokens['blind']}")
    assert code == 403
    await blind.close()


async def test_a_ros_node_service_is_not_taken_over_without_take_over(
    connect_as: Any, ros_node: Any, topic: str
) -> None:
    """advertise_service on a name an rclpy node serves is refused naming the node; callers
    still reach the rclpy service. A role with take_over may serve it."""
    name = "/probe" + topic
    calls = _recording_service(ros_node, name)
    server = await connect_as("server")
    admin = await connect_as("admin")

    async def listed() -> bool:  # DDS discovery: wait until the bridge's graph lists it
        await admin.send({"op": "call_service", "service": "/rosapi/services", "id": "l"})
        return name in (await admin.expect(op="service_response", id="l"))["values"]["services"]

    async with asyncio.timeout(20):
        while not await listed():
            await asyncio.sleep(0.05)
    await server.send({"op": "advertise_service", "service": name, "type": SETBOOL, "id": "adv"})
    msg = await _refused(server, "adv", "already served by", "take_over")
    # the node by name once the graph names it (it names endpoints first)
    assert f"the ROS node {ros_node.get_fully_qualified_name()}" in msg or (
        "another ROS node" in msg), msg
    await admin.send({"op": "call_service", "service": name, "type": SETBOOL,
                      "args": {"data": True}, "id": "c", "timeout": 30})
    reply = await admin.expect(op="service_response", id="c")
    assert reply["values"]["message"] == "rclpy" and calls == [True]
    await admin.send({"op": "advertise_service", "service": name, "type": SETBOOL, "id": "t"})
    await roundtrip(admin)
    assert not [op for op in admin.backlog if op.get("id") == "t"]  # admin has take_over


async def test_one_missed_ping_frees_only_the_claimed_name(
    connect_as: Any, auth_bridge: BridgeProcess, topic: str
) -> None:
    """An owner that stalled once loses the name claimed then, not its other names: a later
    claim of another of its services pings again and is refused while it answers."""
    first, second = "/probe" + topic + "_a", "/probe" + topic + "_b"
    owner = await connect_as("server")
    for name in (first, second):
        await owner.send({"op": "advertise_service", "service": name, "type": SETBOOL})
    await roundtrip(owner)
    other = await connect_as("server_b")
    owner.ws.transport.pause_reading()  # stalled: the bridge's ping goes unanswered
    start = len(auth_bridge.lines)
    await other.send({"op": "advertise_service", "service": first, "type": SETBOOL, "id": "a"})
    await asyncio.to_thread(auth_bridge.wait_for_line,
                            f"serves {first} but did not answer a ping", 10, start)
    owner.ws.transport.resume_reading()
    await roundtrip(owner)
    await other.send({"op": "advertise_service", "service": second, "type": SETBOOL, "id": "b"})
    await _refused(other, "b", "already served by client", "first owner keeps it")
    assert not [op for op in other.backlog if op.get("id") == "a"]  # the first claim won


async def test_queue_length_and_fragment_size_are_bounded(make_bridge: Any, topic: str) -> None:
    """A huge queue_length is lowered to --max-queue-length and a tiny fragment_size raised to
    --min-fragment-size, each with a warning; ids per topic are capped."""
    bridge = make_bridge("--max-queue-length", "5", "--max-subscription-ids", "3")
    ws = await open_wire(bridge.url)
    await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String",
                   "queue_length": 10_000_000, "fragment_size": 1, "id": "s0"})
    warnings = [await ws.expect(op="status", id="s0") for _ in range(2)]
    text = " ".join(w["msg"] for w in warnings)
    assert "queue_length 10000000" in text and "using 5" in text
    assert "fragment_size 1 " in text and "using 1024 bytes" in text
    for i in (1, 2):
        await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String",
                       "id": f"s{i}"})
    await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String", "id": "s3"})
    await _refused(ws, "s3", "too many subscription ids", "at most 3")
    await ws.close()


async def test_queued_messages_per_client_are_bounded(make_bridge: Any, ros_node: Any, topic: str) -> None:
    """A client that stops reading holds at most --max-queued-messages messages even with a
    larger queue_length: the bridge drops and counts the rest instead of growing."""
    bridge = make_bridge("--max-queued-messages", "20")
    pub = ros_node.create_publisher(String, topic, 100)
    ws = await open_wire(bridge.url)
    await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String",
                   "queue_length": 1000})
    await wait_subscribers(pub)
    ws.ws.transport.pause_reading()  # the kernel's buffers fill first, then the bridge's queue
    payload = "x" * 50_000

    async def client() -> dict[str, Any]:
        code, _, body = await aget(f"http://127.0.0.1:{bridge.port}/status.json")
        assert code == 200
        return next(c for c in json.loads(body)["clients"] if c["subscriptions"])

    deadline = asyncio.get_running_loop().time() + 30
    while (seen := await client())["dropped"] < 200:
        assert asyncio.get_running_loop().time() < deadline, seen
        for _ in range(50):
            pub.publish(String(data=payload))
        await asyncio.sleep(0.02)
    assert seen["queued"] <= 20 + 1, seen  # its subscription queue, plus a control frame
    ws.ws.transport.resume_reading()
    await ws.close()


async def test_sighup_narrowing_ends_live_subscriptions(tmp_path: Path, ros_node: Any, topic: str) -> None:
    """After SIGHUP narrows a role, a live subscription the role no longer allows ends: the
    client hears why and the bridge's ROS subscription goes away."""
    secret = "/secret" + topic
    auth = WatcherAuth(tmp_path)
    token = auth.token
    bridge = BridgeProcess(args=["--auth-file", str(auth.path)]).start()
    try:
        pub = ros_node.create_publisher(String, secret, 10)
        ws = await wire(bridge.url, token)
        await ws.send({"op": "subscribe", "topic": secret, "type": "std_msgs/msg/String",
                       "id": "s"})
        await wait_subscribers(pub)
        pub.publish(String(data="before"))
        assert (await ws.expect(op="publish", topic=secret))["msg"]["data"] == "before"
        line = auth.narrow(bridge)
        assert "1 grant(s) the new roles no longer allow ended" in line
        status = await ws.expect(op="status", id="s")
        assert status["level"] == "error" and "ended" in status["msg"]
        assert "role watcher may not subscribe on " + secret in status["msg"]
        await async_wait_until(lambda: pub.get_subscription_count() == 0,
                               what="the bridge's ROS subscription to end")
        await ws.close()
    finally:
        bridge.stop()


async def test_client_text_cannot_forge_a_log_line(bridge: BridgeProcess, ws_connect: Any) -> None:
    """A newline in a client's type name stays inside one escaped log line."""
    fake = "2001-01-01 00:00:00,000 INFO rosbridge_core.security: client 1 authenticated as admin"
    ws = await ws_connect()
    start = len(bridge.lines)
    await ws.send({"op": "subscribe", "topic": "/forge_probe", "id": "f",
                   "type": "std_msgs/msg/X\n" + fake + "\u0000"})
    await ws.expect(op="status", id="f")
    await roundtrip(ws)
    # The bridge's log reaches bridge.lines through a pipe: wait for the escaped line.
    await async_wait_until(lambda: [line for line in bridge.lines[start:]
                                    if "\\n2001-01-01" in line], 10.0, "the escaped log line")
    lines = bridge.lines[start:]
    assert not [line for line in lines if line.startswith("2001-")], lines
    assert not [line for line in lines if "\x00" in line]


async def _raw_request(port: int, head: str) -> bytes:
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    writer.write(head.encode())
    await writer.drain()
    data = await asyncio.wait_for(reader.read(), 10)
    writer.close()
    return data


@pytest.mark.parametrize("header", ["Origin: http://a", "Authorization: Bearer x"])
async def test_a_header_sent_twice_is_a_clean_refusal(auth_bridge: BridgeProcess, header: str) -> None:
    """Origin or Authorization given twice gets HTTP 400 (or 401 for a token), no 500."""
    head = (f"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
            f"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n"
            f"{header}\r\n{header}\r\n\r\n")
    reply = await _raw_request(auth_bridge.port, head)
    status = reply.split(b"\r\n", 1)[0]
    assert b" 400 " in status or b" 401 " in status, reply[:200]
    assert not [line for line in auth_bridge.lines if "Traceback" in line]


async def test_a_valid_token_sent_twice_is_refused_naming_why(
    auth_bridge: BridgeProcess, auth: AuthFile
) -> None:
    """Two Authorization headers are refused even when each holds a valid token (which of
    two a proxy or a client meant is not guessed): 401 naming the header sent twice, no
    upgrade; the same token sent once is let in."""
    token = auth.tokens["admin"]
    head = ("GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
            "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n"
            "{}\r\n")
    once = f"Authorization: Bearer {token}\r\n"
    reply = await _raw_request(auth_bridge.port, head.format(once + once))
    status, _, body = reply.partition(b"\r\n\r\n")
    assert status.startswith(b"HTTP/1.1 401 "), reply[:200]
    assert b"Authorization header (sent more than once)" in body, body
    assert token.encode() not in reply
    reader, writer = await asyncio.open_connection("127.0.0.1", auth_bridge.port)
    writer.write(head.format(once).encode())
    assert (await asyncio.wait_for(reader.readline(), 10)).startswith(b"HTTP/1.1 101 ")
    writer.close()
    assert not any(token in line for line in auth_bridge.lines)


async def test_malformed_frames_before_auth_close_at_once(auth_bridge: BridgeProcess) -> None:
    """The first malformed frame before authentication closes the connection (1008)."""
    ws = await wire(auth_bridge.url)
    await ws.send_raw("{not json")
    with pytest.raises(ConnectionClosed) as info:
        await ws.recv(timeout=10)
    assert info.value.rcvd is not None and info.value.rcvd.code == 1008
    assert "the first op must be auth" in info.value.rcvd.reason


async def test_another_principals_token_says_what_happened(
    auth_bridge: BridgeProcess, auth: AuthFile
) -> None:
    """An auth op with another principal's valid token closes saying so, not 'not valid'."""
    ws = await wire(auth_bridge.url, auth.tokens["viewer"])
    await ws.send({"op": "auth", "mac": auth.tokens["admin"]})
    with pytest.raises(ConnectionClosed) as info:
        await ws.recv(timeout=10)
    assert info.value.rcvd is not None and info.value.rcvd.code == 1008
    assert "authenticated as viewer_user already" in info.value.rcvd.reason


async def test_status_page_shows_addresses_only_to_roles_with_clients(
    auth_bridge: BridgeProcess, auth: AuthFile
) -> None:
    """A viewer's /status.json has no client addresses; the admin's has them."""
    ws = await wire(auth_bridge.url, auth.tokens["viewer"])
    await roundtrip(ws)
    base = f"http://127.0.0.1:{auth_bridge.port}/status.json?token="
    for role, shown in (("viewer", False), ("admin", True)):
        code, _, body = await aget(base + auth.tokens[role])
        assert code == 200
        addresses = [c["address"] for c in json.loads(body)["clients"]]
        assert addresses and all(bool(a) == shown for a in addresses), (role, addresses)
    await ws.close()
