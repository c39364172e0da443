"""The stock Foxglove WebSocket client (``@foxglove/ws-protocol`` from npm, unchanged) in Node
against our bridge on the rosbridge port, with rclpy on the ROS side.

The Node driver is ``tests/peers/node/foxglove_peer.mjs``; it decodes and encodes CDR with
``@foxglove/rosmsg2-serialization`` from the schemas the bridge advertises, so a message
that arrives equal to what rclpy published shows that the channel, its schema and the raw
bytes all agree.
"""

from __future__ import annotations

import base64
import functools
import itertools
import json
import queue
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from bridge_server.foxglove.hub import foxglove_schema
from msgs import dynamic
from tests.helpers import BridgeProcess, wait_until
from tests.peers import scenarios
from tests.peers.peer import PeerPool, PeerProcess, foxglove_peer
from tests.security.support import WatcherAuth, make_auth_file

DEADLINE = scenarios.DEADLINE


@pytest.fixture
def fox(peer_pool: PeerPool) -> PeerProcess:
    """The module's connected Foxglove client, ready for this test."""
    return peer_pool.get("foxglove")


def _schema(type_name: str) -> str:
    """The definition text of a type as Foxglove clients take it."""
    return foxglove_schema(dynamic.full_text(type_name))


def _messages(peer: PeerProcess, topic: str) -> list[dict[str, Any]]:
    return [e for e in peer.new_events() if e.get("event") == "message" and e["topic"] == topic]


def _errors(peer: PeerProcess) -> list[str]:
    return [e["message"] for e in peer.new_events()
            if e.get("event") == "status" and e.get("level") == 2]


def _wait_error(peer: PeerProcess, part: str) -> str:
    event = peer.wait_event(lambda e: e.get("event") == "status" and e.get("level") == 2
                            and part in e.get("message", ""), DEADLINE, f"status error '{part}'")
    return str(event["message"])


def _publish_until_seen(peer: PeerProcess, pub: Any, topic: str, msg: Any) -> dict[str, Any]:
    """Publish from rclpy until the client has a message on ``topic`` (DDS matching)."""
    deadline = time.monotonic() + DEADLINE
    while time.monotonic() < deadline:
        pub.publish(msg)
        try:
            return peer.wait_event(lambda e: e.get("event") == "message" and e["topic"] == topic,
                                   scenarios.ATTEMPT, f"message on {topic}")
        except AssertionError:
            continue
    raise AssertionError(f"no message on {topic}\n{peer.diagnostics()}")


def _serving_on(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """The connection is open and the bridge still serves it: a new subscription works."""
    from std_msgs.msg import String

    assert peer.request("is_open") is True
    pub = ros_node.create_publisher(String, topic + "_alive", 10)
    peer.request("subscribe", topic=topic + "_alive", timeout_ms=int(DEADLINE * 1000))
    assert _publish_until_seen(peer, pub, topic + "_alive", String(data="alive"))["msg"] == {
        "data": "alive"}


# -- the handshake -------------------------------------------------------------------------------


def test_server_info(fox: PeerProcess) -> None:
    """The client offering foxglove.websocket.v1 gets it, and a serverInfo with what we do."""
    assert fox.info["protocol"] == "foxglove.websocket.v1"
    info = fox.info["serverInfo"]
    assert {"clientPublish", "parameters", "parametersSubscribe", "services",
            "connectionGraph"} <= set(info["capabilities"])
    assert "assets" not in info["capabilities"]
    assert info["supportedEncodings"] == ["cdr", "json"]


def test_channels_have_full_schemas(fox: PeerProcess, ros_node: Any, topic: str) -> None:
    """An rclpy publisher's topic is advertised as a cdr channel with the ros2msg definition
    text, its dependencies included."""
    from sensor_msgs.msg import Image

    ros_node.create_publisher(Image, topic, 10)
    channel = fox.request("wait_channel", topic=topic, timeout_ms=int(DEADLINE * 1000))
    assert channel["encoding"] == "cdr"
    assert channel["schemaEncoding"] == "ros2msg"
    assert channel["schemaName"] == "sensor_msgs/msg/Image"
    schema = channel["schema"]
    assert "uint32 height" in schema
    # dependencies as the fields name them, the spelling @foxglove/rosmsg matches
    assert "MSG: std_msgs/Header" in schema and "MSG: builtin_interfaces/Time" in schema


def test_channel_goes_with_its_topic(fox: PeerProcess, ros_node: Any, topic: str) -> None:
    """When the last publisher of a topic goes, the client is told the channel went."""
    from std_msgs.msg import String

    pub = ros_node.create_publisher(String, topic, 10)
    channel = fox.request("wait_channel", topic=topic, timeout_ms=int(DEADLINE * 1000))
    ros_node.destroy_publisher(pub)
    fox.wait_event(lambda e: e.get("event") == "unadvertise"
                   and channel["id"] in e["channelIds"], DEADLINE, "unadvertise")


# -- subscribing ---------------------------------------------------------------------------------


def test_subscribe_image(fox: PeerProcess, ros_node: Any, topic: str) -> None:
    """A 640x480 rgb8 Image arrives as CDR that the client decodes to what rclpy published."""
    from sensor_msgs.msg import Image

    pub = ros_node.create_publisher(Image, topic, 10)
    fox.request("subscribe", topic=topic, timeout_ms=int(DEADLINE * 1000))
    img = Image(height=480, width=640, encoding="rgb8", step=640 * 3, is_bigendian=0)
    img.header.frame_id = "camera"
    img.header.stamp.sec, img.header.stamp.nanosec = 12, 345
    pixels = bytes(i * 7 % 251 for i in range(640 * 480 * 3))
    img.data = pixels
    event = _publish_until_seen(fox, pub, topic, img)
    msg = event["msg"]
    assert msg["header"] == {"stamp": {"sec": 12, "nanosec": 345}, "frame_id": "camera"}
    assert (msg["height"], msg["width"], msg["encoding"], msg["step"]) == (480, 640, "rgb8",
                                                                            1920)
    assert base64.b64decode(msg["data"]["$bytes"]) == pixels
    stamp = int(event["timestamp"]["$bigint"])  # the receive time, in ns
    assert abs(stamp - time.time_ns()) < 60 * 10**9


def test_subscribe_imu(fox: PeerProcess, ros_node: Any, topic: str) -> None:
    """An Imu (nested messages, float64[9] covariances) decodes to rclpy's numbers."""
    from sensor_msgs.msg import Imu

    pub = ros_node.create_publisher(Imu, topic, 10)
    fox.request("subscribe", topic=topic, timeout_ms=int(DEADLINE * 1000))
    imu = Imu()
    imu.header.frame_id = "imu_link"
    imu.orientation.x, imu.orientation.w = 0.25, 0.75
    imu.angular_velocity.z = -1.5
    imu.linear_acceleration.z = 9.81
    imu.orientation_covariance = [float(i) / 8 for i in range(9)]
    msg = _publish_until_seen(fox, pub, topic, imu)["msg"]
    assert msg["header"]["frame_id"] == "imu_link"
    assert msg["orientation"] == {"x": 0.25, "y": 0.0, "z": 0.0, "w": 0.75}
    assert msg["angular_velocity"]["z"] == -1.5
    assert msg["linear_acceleration"]["z"] == 9.81
    assert msg["orientation_covariance"]["values"] == [float(i) / 8 for i in range(9)]


def test_unsubscribe(fox: PeerProcess, ros_node: Any, topic: str) -> None:
    """After unsubscribe the bridge drops its ROS subscription of the topic."""
    from std_msgs.msg import String

    pub = ros_node.create_publisher(String, topic, 10)
    fox.request("subscribe", topic=topic, timeout_ms=int(DEADLINE * 1000))
    _publish_until_seen(fox, pub, topic, String(data="x"))
    fox.request("unsubscribe", topic=topic)
    wait_until(lambda: pub.get_subscription_count() == 0, DEADLINE, "the bridge to unsubscribe")


# -- publishing, services, parameters ----------------------------------------------------------


def test_client_publishes(fox: PeerProcess, ros_node: Any, topic: str) -> None:
    """clientAdvertise and binary CDR message data reach an rclpy subscriber."""
    from geometry_msgs.msg import Twist

    inbox: queue.Queue[Any] = queue.Queue()
    ros_node.create_subscription(Twist, topic, inbox.put, 10)
    fox.request("advertise", topic=topic, schemaName="geometry_msgs/msg/Twist",
                schema=_schema("geometry_msgs/msg/Twist"))
    sent = {"linear": {"x": 1.5, "y": 0, "z": 0}, "angular": {"x": 0, "y": 0, "z": -0.5}}
    deadline = time.monotonic() + DEADLINE
    got = None
    while got is None and time.monotonic() < deadline:
        fox.request("publish", topic=topic, msg=sent)
        try:
            got = inbox.get(timeout=scenarios.ATTEMPT)
        except queue.Empty:
            assert not _errors(fox), _errors(fox)
    assert got is not None, fox.diagnostics()
    assert (got.linear.x, got.angular.z) == (1.5, -0.5)
    fox.request("unadvertise", topic=topic)


def test_call_service(fox: PeerProcess, ros_node: Any, topic: str) -> None:
    """An rclpy SetBool service is advertised, and a CDR call gets its CDR answer."""
    from std_srvs.srv import SetBool

    def answer(request: Any, response: Any) -> Any:
        response.success = request.data
        response.message = f"rclpy got {request.data}"
        return response

    ros_node.create_service(SetBool, topic, answer)
    service = fox.request("service", service=topic, timeout_ms=int(DEADLINE * 1000))
    assert service["type"] == "std_srvs/srv/SetBool"
    assert service["request"]["schemaName"] == "std_srvs/srv/SetBool_Request"
    reply = fox.request("call_service", service=topic, request={"data": True},
                        timeout=DEADLINE)
    assert reply == {"encoding": "cdr", "value": {"success": True, "message": "rclpy got True"}}


def test_what_goes_is_withdrawn(fox: PeerProcess, ros_node: Any, topic: str) -> None:
    """A service whose server goes is unadvertised to the client; a client channel it
    unadvertises takes the bridge's ROS publisher with it."""
    from std_srvs.srv import SetBool

    server = ros_node.create_service(SetBool, topic + "_srv", lambda req, res: res)
    service = fox.request("service", service=topic + "_srv", timeout_ms=int(DEADLINE * 1000))
    ros_node.destroy_service(server)
    fox.wait_event(lambda e: e.get("event") == "unadvertiseServices"
                   and service["id"] in e["serviceIds"], DEADLINE, "unadvertiseServices")
    fox.request("advertise", topic=topic, schemaName="std_msgs/msg/String",
                schema=_schema("std_msgs/msg/String"))
    wait_until(lambda: ros_node.count_publishers(topic) == 1, DEADLINE, "the bridge's publisher")
    fox.request("unadvertise", topic=topic)
    wait_until(lambda: ros_node.count_publishers(topic) == 0, DEADLINE,
               "the bridge's publisher to go")


def _parameter_values(fox: PeerProcess, request_id: str, cmd: str, **params: Any
                      ) -> list[dict[str, Any]]:
    """Send a parameter command with ``request_id``; the ``parameterValues`` answering it."""
    fox.request(cmd, id=request_id, **params)
    event = fox.wait_event(lambda e: e.get("event") == "parameterValues"
                           and e["id"] == request_id, DEADLINE, f"parameterValues {request_id}")
    found: list[dict[str, Any]] = event["parameters"]
    return found


def _update(fox: PeerProcess, entry: dict[str, Any], timeout: float = DEADLINE) -> None:
    """Wait for a parameter update event (no id) that holds ``entry``."""
    fox.wait_event(lambda e: e.get("event") == "parameterValues" and e["id"] is None
                   and entry in e["parameters"], timeout, f"an update with {entry}")


def test_parameters(fox: PeerProcess, ros_node: Any, topic: str) -> None:
    """A node's parameters of every type are read as the spec has them (one by one and all
    at once), set (the node sees it) and followed (/node.param names); a byte array reads,
    sets and follows as base64 text typed byte_array, whoever set it."""
    from rclpy.parameter import Parameter

    prefix = topic.strip("/").replace("/", "_") + "_"
    declared = scenarios.declare_foxglove_parameters(ros_node, prefix)
    names = [name for name, _ in declared]
    entries = [entry for _, entry in declared]
    full, blob = (f"{ros_node.get_fully_qualified_name()}.{prefix}{short}"
                  for short in ("gain", "blob"))
    try:
        fox.request("subscribe_parameters", names=[full, blob])
        deadline = time.monotonic() + DEADLINE
        n = 0
        while not (values := _parameter_values(fox, f"get{n}", "get_parameters", names=names)):
            assert time.monotonic() < deadline, "the bridge never saw the node"
            n += 1  # until the bridge sees the node (no event)
        assert values == entries
        every = _parameter_values(fox, "all", "get_parameters", names=[])
        assert [p for p in every if p["name"] in names] == entries
        assert _parameter_values(fox, "set1", "set_parameters", parameters=[
            {"name": full, "value": 3, "type": "float64"}]) == [
            {"name": full, "value": 3.0, "type": "float64"}]
        assert ros_node.get_parameter(prefix + "gain").value == 3.0
        _update(fox, {"name": full, "value": 3.0, "type": "float64"})
        hi = {"name": blob, "value": "aGk=", "type": "byte_array"}
        assert _parameter_values(fox, "set2", "set_parameters", parameters=[hi]) == [hi]
        assert ros_node.get_parameter(prefix + "blob").value == [b"h", b"i"]
        _update(fox, hi)
        by_ros = Parameter(prefix + "blob", Parameter.Type.BYTE_ARRAY,  # type: ignore[no-untyped-call]
                           [b"r", b"o", b"s"])
        ros_node.set_parameters([by_ros])
        ros = {"name": blob, "value": "cm9z", "type": "byte_array"}
        _update(fox, ros)
        assert _parameter_values(fox, "get_blob", "get_parameters", names=[blob]) == [ros]
    finally:
        for name, _, _ in scenarios.FOXGLOVE_PARAMETERS:
            ros_node.undeclare_parameter(prefix + name)


def test_connection_graph(fox: PeerProcess, ros_node: Any, topic: str) -> None:
    """A connection graph update names the rclpy node publishing a topic."""
    from std_msgs.msg import String

    ros_node.create_publisher(String, topic, 10)
    fox.request("wait_channel", topic=topic, timeout_ms=int(DEADLINE * 1000))
    fox.request("subscribe_graph")
    me = f"/{ros_node.get_name()}"
    fox.wait_event(lambda e: e.get("event") == "connectionGraphUpdate" and any(
        t["name"] == topic and me in t["publisherIds"]
        for t in e["update"]["publishedTopics"]), DEADLINE, "a graph update with the topic")


def test_rosbridge_and_foxglove_at_once(fox: PeerProcess, peer_pool: PeerPool, ros_node: Any,
                                        topic: str, bridge: BridgeProcess) -> None:
    """A roslib client and a Foxglove client on one bridge get the same topic each their way,
    and the status page lists each with its protocol."""
    import json
    import urllib.request

    from std_msgs.msg import String

    roslib = peer_pool.get("roslib")
    pub = ros_node.create_publisher(String, topic, 10)
    roslib.request("subscribe", topic=topic, type="std_msgs/msg/String")
    fox.request("subscribe", topic=topic, timeout_ms=int(DEADLINE * 1000))
    deadline = time.monotonic() + DEADLINE
    while time.monotonic() < deadline and not (
            _messages(fox, topic) and [e for e in roslib.new_events()
                                       if e.get("event") == "message"]):
        pub.publish(String(data="both"))
        time.sleep(scenarios.ATTEMPT)  # publish again until both were matched (DDS)
    assert _messages(fox, topic)[0]["msg"] == {"data": "both"}
    assert next(e for e in roslib.new_events() if e.get("event") == "message")["msg"] == {
        "data": "both"}
    with urllib.request.urlopen(bridge.url.replace("ws:", "http:") + "/status.json",
                                timeout=DEADLINE) as response:
        status = json.load(response)
    protocols = {c["protocol"] for c in status["clients"]}
    assert {"rosbridge", "foxglove"} <= protocols


# -- bad input -----------------------------------------------------------------------------------


def test_bad_frames_get_status_errors(fox: PeerProcess, ros_node: Any, topic: str) -> None:
    """Malformed JSON, an unknown op, bad binary opcodes, unknown channel, subscription and
    service ids: each answered with a status error naming it; the connection serves on."""
    cases: list[tuple[str, dict[str, Any], str]] = [
        ("send_text", {"text": "{not json"}, "malformed JSON at line 1 column 2"),
        ("send_text", {"text": '{"op": "frobnicate"}'}, "unknown op 'frobnicate'"),
        ("send_text", {"text": '{"op": "subscribe", "subscriptions": [{"id": "x"}]}'},
         "subscribe.subscriptions[0].id"),
        ("send_binary", {"hex": "07aabb"}, "unknown binary opcode 0x07"),
        ("send_binary", {"hex": "01aa"}, "too short"),
        ("send_text", {"text": '{"op": "subscribe", "subscriptions": [{"id": 9, '
                               '"channelId": 999999}]}'}, "no channel 999999"),
        ("send_text", {"text": '{"op": "unsubscribe", "subscriptionIds": [424242]}'},
         "no subscription 424242"),
        ("send_binary", {"hex": "01" + "39300000" + "00010000"}, "no client channel 12345"),
    ]
    for cmd, params, part in cases:
        fox.request(cmd, timeout=DEADLINE, **params)
        _wait_error(fox, part)
    with pytest.raises(Exception, match="no service 777"):
        fox.request("call_service_id", service_id=777, hex="00010000")
    _serving_on(fox, ros_node, topic)


def test_deep_nesting_is_a_status_error(fox: PeerProcess, bridge: BridgeProcess,
                                        ros_node: Any, topic: str) -> None:
    """JSON nested 5,000 deep, as a frame or as a json client channel's message, is answered
    with a status error in rosbridge's words ("nested too deeply"); no traceback is logged,
    and that client and another one serve on."""
    other = foxglove_peer(bridge.url, bridge)
    try:
        start = len(bridge.lines)
        deep = "[" * 5000 + "]" * 5000
        fox.request("send_text", text='{"op": "subscribe", "subscriptions": ' + deep + "}")
        assert _wait_error(fox, "nested too deeply") == "malformed JSON: nested too deeply"
        fox.request("advertise", topic=topic, schemaName="std_msgs/msg/String", encoding="json")
        fox.request("publish_bytes", topic=topic, hex=deep.encode().hex())
        _wait_error(fox, f"message data on {topic} (std_msgs/msg/String, json): not published: "
                         "malformed JSON: nested too deeply")
        assert not [line for line in bridge.lines[start:] if "Traceback" in line]
        _serving_on(fox, ros_node, topic)
        _serving_on(other, ros_node, topic + "_other")
    finally:
        other.close()


def test_bad_cdr_is_not_published(fox: PeerProcess, ros_node: Any, topic: str) -> None:
    """Truncated CDR on a client channel is refused with a status error; rclpy gets nothing."""
    from std_msgs.msg import String

    inbox: queue.Queue[Any] = queue.Queue()
    ros_node.create_subscription(String, topic, inbox.put, 10)
    fox.request("advertise", topic=topic, schemaName="std_msgs/msg/String",
                schema=_schema("std_msgs/msg/String"))
    fox.request("publish_bytes", topic=topic, hex="00010000ff000000")  # a 255-byte string: cut
    _wait_error(fox, f"message data on {topic}")
    deadline = time.monotonic() + DEADLINE
    while inbox.empty() and time.monotonic() < deadline:  # good ones go through (once matched)
        fox.request("publish", topic=topic, msg={"data": "good"})
        time.sleep(scenarios.ATTEMPT)
    assert {m.data for m in list(inbox.queue)} == {"good"}


@pytest.fixture(scope="module")
def secured(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[BridgeProcess, Any]]:
    """A bridge with an auth file and a small message size limit."""
    tmp: Path = tmp_path_factory.mktemp("foxglove_auth")
    auth = make_auth_file(tmp)
    proc = BridgeProcess(args=["--auth-file", str(auth.path), "--max-message-size", "65536",
                               "--max-publishers", "2"])
    proc.start()
    yield proc, auth
    proc.stop()


def test_token_in_query_string(secured: tuple[BridgeProcess, Any], ros_node: Any,
                               topic: str) -> None:
    """A token in ?token= opens a Foxglove session; without one the bridge closes it (1008)."""
    bridge, auth = secured
    with pytest.raises(AssertionError, match=r"could not connect.*1008"):
        foxglove_peer(bridge.url, bridge)
    peer = foxglove_peer(f"{bridge.url}/?token={auth.tokens['tester']}", bridge)
    try:
        assert peer.info["protocol"] == "foxglove.websocket.v1"
    finally:
        peer.close()
    assert auth.tokens["tester"] not in "\n".join(bridge.lines)


def test_forbidden_publish_and_oversize(secured: tuple[BridgeProcess, Any], ros_node: Any,
                                        topic: str) -> None:
    """A publish the role forbids and a client message over the size limit each get a status
    error; nothing reaches ROS; the client serves on."""
    from std_msgs.msg import String

    bridge, auth = secured
    peer = foxglove_peer(f"{bridge.url}/?token={auth.tokens['tester']}", bridge)
    try:
        inbox: queue.Queue[Any] = queue.Queue()
        ros_node.create_subscription(String, "/op/forbidden", inbox.put, 10)
        peer.request("advertise", topic="/op/forbidden", schemaName="std_msgs/msg/String",
                     schema=_schema("std_msgs/msg/String"))
        _wait_error(peer, "forbidden: role tester may not publish on /op/forbidden")
        peer.request("publish_bytes", channel=1, hex="00010000030000006869000000")
        _wait_error(peer, "no client channel")
        peer.request("advertise", topic="/op" + topic, schemaName="std_msgs/msg/String",
                     schema=_schema("std_msgs/msg/String"))
        peer.request("send_big", channel=2, size=100_000)
        _wait_error(peer, "over this bridge's limit of 65536 bytes")
        assert inbox.empty()
        _serving_on(peer, ros_node, "/op" + topic)
    finally:
        peer.close()


def test_role_decides_what_is_shown(secured: tuple[BridgeProcess, Any], ros_node: Any,
                                    topic: str) -> None:
    """A role that may subscribe only to /probe/* is shown only those channels, and its
    subscribe to another channel's id (learnt elsewhere) is refused as forbidden."""
    from std_msgs.msg import String

    bridge, auth = secured
    ros_node.create_publisher(String, "/probe" + topic, 10)
    ros_node.create_publisher(String, topic, 10)
    tester = foxglove_peer(f"{bridge.url}/?token={auth.tokens['tester']}", bridge)
    try:
        tester.request("wait_channel", topic="/probe" + topic, timeout_ms=int(DEADLINE * 1000))
        other = tester.request("wait_channel", topic=topic, timeout_ms=int(DEADLINE * 1000))
    finally:
        tester.close()
    prober = foxglove_peer(f"{bridge.url}/?token={auth.tokens['prober']}", bridge)
    try:
        first = prober.wait_event(lambda e: e.get("event") == "advertise", DEADLINE, "advertise")
        shown = {c["topic"] for c in first["channels"]}
        assert "/probe" + topic in shown and topic not in shown
        assert all(t.startswith("/probe/") for t in shown), shown
        prober.request("send_text", text=json.dumps(
            {"op": "subscribe", "subscriptions": [{"id": 1, "channelId": other["id"]}]}))
        _wait_error(prober, f"{topic}: forbidden: role prober may not subscribe")
    finally:
        prober.close()


def test_publisher_limit(secured: tuple[BridgeProcess, Any], topic: str) -> None:
    """--max-publishers holds for Foxglove client channels: the third topic is refused."""
    bridge, auth = secured
    peer = foxglove_peer(f"{bridge.url}/?token={auth.tokens['tester']}", bridge)
    try:
        for n in range(3):
            peer.request("advertise", topic=f"/op{topic}_{n}", schemaName="std_msgs/msg/String",
                         schema=_schema("std_msgs/msg/String"))
        _wait_error(peer, f"/op{topic}_2): too many publishers on this connection (at most 2)")
        assert len([m for m in _errors(peer) if "too many publishers" in m]) == 1
    finally:
        peer.close()


def test_json_publish_and_bad_service_request(fox: PeerProcess, ros_node: Any,
                                              topic: str) -> None:
    """A client channel in json encoding reaches rclpy; a service request whose CDR does not
    decode gets a serviceCallFailure naming the type, and nothing is called."""
    from std_msgs.msg import String
    from std_srvs.srv import SetBool

    inbox: queue.Queue[Any] = queue.Queue()
    ros_node.create_subscription(String, topic, inbox.put, 10)
    fox.request("advertise", topic=topic, schemaName="std_msgs/msg/String", encoding="json")
    deadline = time.monotonic() + DEADLINE
    while inbox.empty() and time.monotonic() < deadline:
        fox.request("publish", topic=topic, msg={"data": "as json"})
        time.sleep(scenarios.ATTEMPT)  # until the bridge's publisher is matched (DDS)
    assert inbox.get_nowait().data == "as json"
    calls: list[Any] = []

    def answer(request: Any, response: Any) -> Any:
        calls.append(request)
        return response

    ros_node.create_service(SetBool, topic + "_srv", answer)
    service = fox.request("service", service=topic + "_srv", timeout_ms=int(DEADLINE * 1000))
    with pytest.raises(Exception, match="does not decode as std_srvs/srv/SetBool"):
        fox.request("call_service_id", service_id=service["id"], hex="0001")
    assert calls == []


def test_sighup_ends_what_the_role_no_longer_allows(tmp_path: Path, ros_node: Any,
                                                    topic: str) -> None:
    """After SIGHUP narrows the role, a Foxglove client's live subscription it no longer
    allows ends: the client hears why, and the bridge's ROS subscription goes."""
    from std_msgs.msg import String

    auth = WatcherAuth(tmp_path)
    bridge = BridgeProcess(args=["--auth-file", str(auth.path)]).start()
    try:
        pub = ros_node.create_publisher(String, "/secret" + topic, 10)
        peer = foxglove_peer(f"{bridge.url}/?token={auth.token}", bridge)
        try:
            peer.request("subscribe", topic="/secret" + topic, timeout_ms=int(DEADLINE * 1000))
            _publish_until_seen(peer, pub, "/secret" + topic, String(data="before"))
            line = auth.narrow(bridge)
            assert "1 grant(s) the new roles no longer allow ended" in line
            _wait_error(peer, f"/secret{topic} ended: role watcher may not subscribe")
            wait_until(lambda: pub.get_subscription_count() == 0, DEADLINE,
                       "the bridge's ROS subscription to end")
        finally:
            peer.close()
    finally:
        bridge.stop()


# -- what a role sees and reaches, as over rosbridge ------------------------------------------------


def _as(secured: tuple[BridgeProcess, Any], role: str) -> PeerProcess:
    """A Foxglove client of the ``secured`` bridge with the token of ``role``'s principal."""
    bridge, auth = secured
    return foxglove_peer(f"{bridge.url}/?token={auth.tokens[role]}", bridge)


def _all_sent(peer: PeerProcess) -> list[dict[str, Any]]:
    """The client's events once it has the answer to a frame sent now: all that the bridge
    sent it before that frame (it answers each client's frames in order)."""
    peer.request("send_text", text='{"op": "barrier"}')
    _wait_error(peer, "unknown op 'barrier'")
    return peer.new_events()


def _graph_names(events: list[dict[str, Any]]) -> set[str]:
    """Every topic, service and node named by the connection graph updates among ``events``."""
    names: set[str] = set()
    for event in events:
        if event.get("event") != "connectionGraphUpdate":
            continue
        update = event["update"]
        for key, ids in (("publishedTopics", "publisherIds"), ("subscribedTopics",
                                                               "subscriberIds"),
                         ("advertisedServices", "providerIds")):
            for entry in update[key]:
                names.add(entry["name"])
                names.update(entry[ids])
        names.update(update["removedTopics"], update["removedServices"])
    return names


def _rosbridge_refusal(bridge: BridgeProcess, token: str, service: str) -> str:
    """The status error a rosbridge client with ``token`` gets for calling ``service``."""
    from websockets.sync.client import connect

    with connect(bridge.url, additional_headers={"Authorization": f"Bearer {token}"},
                 open_timeout=DEADLINE) as ws:
        ws.send(json.dumps({"op": "call_service", "service": service, "id": "r"}))
        while True:
            reply = json.loads(ws.recv(DEADLINE))
            if reply.get("op") == "status" and reply.get("level") == "error":
                return str(reply["msg"])


def _published_by(topic: str, node: str) -> Any:
    """A predicate: a graph update in which ``node`` publishes ``topic``."""
    return lambda e: e.get("event") == "connectionGraphUpdate" and any(
        t["name"] == topic and node in t["publisherIds"]
        for t in e["update"]["publishedTopics"])


def test_connection_graph_needs_introspection(secured: tuple[BridgeProcess, Any],
                                              ros_node: Any, topic: str) -> None:
    """A role without introspection (it may subscribe to anything) is not offered
    connectionGraph, and its subscribeConnectionGraph is refused in the words rosbridge
    refuses it /rosapi/nodes in: no graph update reaches it; admin's follows the graph."""
    from std_msgs.msg import String

    bridge, auth = secured
    ros_node.create_publisher(String, topic, 10)
    why = "forbidden: role tester may not introspection on any name"
    assert why in _rosbridge_refusal(bridge, auth.tokens["tester"], "/rosapi/nodes")
    tester = _as(secured, "tester")
    try:
        assert "connectionGraph" not in tester.info["serverInfo"]["capabilities"]
        tester.request("wait_channel", topic=topic, timeout_ms=int(DEADLINE * 1000))
        tester.request("subscribe_graph")
        assert f"subscribeConnectionGraph: {why}" in _wait_error(tester, why)
        assert _graph_names(_all_sent(tester)) == set()
    finally:
        tester.close()
    admin = _as(secured, "admin")
    try:
        assert "connectionGraph" in admin.info["serverInfo"]["capabilities"]
        admin.request("subscribe_graph")
        admin.wait_event(_published_by(topic, ros_node.get_fully_qualified_name()), DEADLINE,
                         "a graph update with the topic")
    finally:
        admin.close()


def test_connection_graph_shows_only_what_the_role_sees(secured: tuple[BridgeProcess, Any],
                                                        ros_node: Any, topic: str) -> None:
    """A role with introspection on /seen* only follows a connection graph that names its
    /seen* topics, services and nodes and nothing else (not the /seen node's other topic,
    nor the node subscribing from outside /seen*), as rosapi's lists would."""
    import rclpy
    from std_msgs.msg import String
    from std_srvs.srv import SetBool

    seen_node = rclpy.create_node("seen" + topic.replace("/", "_"), context=ros_node.context)
    try:
        seen_id = seen_node.get_fully_qualified_name()
        seen_node.create_publisher(String, "/seen" + topic, 10)
        seen_node.create_publisher(String, topic, 10)
        seen_node.create_service(SetBool, "/seen" + topic + "_srv", lambda req, res: res)
        ros_node.create_subscription(String, "/seen" + topic, lambda msg: None, 10)
        narrow = _as(secured, "narrow")
        try:
            assert "connectionGraph" in narrow.info["serverInfo"]["capabilities"]
            narrow.request("subscribe_graph")
            narrow.wait_event(_published_by("/seen" + topic, seen_id), DEADLINE,
                              "a graph update with the /seen topic")
            narrow.wait_event(lambda e: e.get("event") == "connectionGraphUpdate" and any(
                s["name"] == "/seen" + topic + "_srv" and seen_id in s["providerIds"]
                for s in e["update"]["advertisedServices"]), DEADLINE, "the /seen service")
            names = _graph_names(_all_sent(narrow))
            assert {"/seen" + topic, "/seen" + topic + "_srv", seen_id} <= names
            assert [n for n in names if not n.startswith("/seen")] == []
        finally:
            narrow.close()
    finally:
        seen_node.destroy_node()  # type: ignore[no-untyped-call]


def test_call_the_role_may_not_make_never_runs(secured: tuple[BridgeProcess, Any],
                                               ros_node: Any, topic: str) -> None:
    """A role that may call only /probe/* services calls another service by the id an admin
    connection learnt: a serviceCallFailure says forbidden and the rclpy handler never runs
    (it does for the admin's call)."""
    from std_srvs.srv import SetBool

    calls: list[bool] = []

    def answer(request: Any, response: Any) -> Any:
        calls.append(request.data)
        response.success = True
        return response

    ros_node.create_service(SetBool, topic, answer)
    admin = _as(secured, "admin")
    try:
        service = admin.request("service", service=topic, timeout_ms=int(DEADLINE * 1000))
        prober = _as(secured, "prober")
        try:
            with pytest.raises(Exception, match=f"forbidden: role prober may not call_service "
                                                f"on {topic}"):
                prober.request("call_service_id", service_id=service["id"], hex="0001000001",
                               timeout=DEADLINE)
        finally:
            prober.close()
        assert admin.request("call_service", service=topic, request={"data": False},
                             timeout=DEADLINE)["value"]["success"] is True
        assert calls == [False]  # only the admin's call reached the service
    finally:
        admin.close()


def test_parameter_lists_need_params(secured: tuple[BridgeProcess, Any], ros_node: Any,
                                     topic: str) -> None:
    """A role without params is not offered the parameter capabilities, and its
    getParameters and subscribeParameterUpdates of every parameter are refused in the words
    rosbridge refuses it /rosapi/get_param_names in (the request's id answered with no
    values); a role with params on *_display names gets those names only."""
    bridge, auth = secured
    why = "forbidden: role tester may not params on any name"
    assert why in _rosbridge_refusal(bridge, auth.tokens["tester"], "/rosapi/get_param_names")
    tester = _as(secured, "tester")
    try:
        assert not {"parameters", "parametersSubscribe"} & set(
            tester.info["serverInfo"]["capabilities"])
        assert _parameter_values(tester, "all", "get_parameters", names=[]) == []
        assert f"getParameters: {why}" in _wait_error(tester, "getParameters")
        tester.request("subscribe_parameters", names=[])
        assert f"subscribeParameterUpdates: {why}" in _wait_error(tester,
                                                                  "subscribeParameterUpdates")
    finally:
        tester.close()
    prefix = topic.strip("/").replace("/", "_")
    ros_node.declare_parameter(prefix + "_display", 1.0)
    ros_node.declare_parameter(prefix + "_secret", 2.0)
    node = ros_node.get_fully_qualified_name()
    prober = _as(secured, "prober")
    try:
        assert {"parameters", "parametersSubscribe"} <= set(
            prober.info["serverInfo"]["capabilities"])
        deadline = time.monotonic() + DEADLINE
        for n in itertools.count():  # until the bridge sees the node's parameters
            names = {p["name"] for p in _parameter_values(prober, f"all{n}", "get_parameters",
                                                          names=[])}
            if f"{node}.{prefix}_display" in names:
                break
            assert time.monotonic() < deadline, names
        assert names and all(name.endswith("_display") for name in names), names
    finally:
        prober.close()
        ros_node.undeclare_parameter(prefix + "_display")
        ros_node.undeclare_parameter(prefix + "_secret")


def test_follow_all_parameters(bridge: BridgeProcess, ros_node: Any, topic: str) -> None:
    """subscribeParameterUpdates with no names follows every parameter: a parameter changed
    in ROS comes as an update, named /node.param."""
    from rclpy.parameter import Parameter

    name = topic.strip("/").replace("/", "_") + "_gain"
    ros_node.declare_parameter(name, 0.0)
    full = f"{ros_node.get_fully_qualified_name()}.{name}"
    peer = foxglove_peer(bridge.url, bridge)
    try:
        peer.request("subscribe_parameters", names=[])
        deadline = time.monotonic() + DEADLINE
        for n in itertools.count(1):  # until the bridge's /parameter_events reader is matched
            ros_node.set_parameters([Parameter(name, value=float(n))])  # type: ignore[no-untyped-call]
            entry = {"name": full, "value": float(n), "type": "float64"}
            try:
                _update(peer, entry, scenarios.ATTEMPT)
                break
            except AssertionError:
                assert time.monotonic() < deadline, f"no update of {full}\n{peer.diagnostics()}"
    finally:
        peer.close()
        ros_node.undeclare_parameter(name)


# -- slow clients, time ----------------------------------------------------------------------------


def _status(bridge: BridgeProcess) -> Any:
    import urllib.request

    with urllib.request.urlopen(bridge.url.replace("ws:", "http:") + "/status.json",
                                timeout=DEADLINE) as response:
        return json.load(response)


def _bridge_received(bridge: BridgeProcess, topic: str, count: int) -> bool:
    """Whether the bridge has received ``count`` messages of ``topic`` from ROS."""
    return bool(_status(bridge)["topics"][topic]["ros_received"] >= count)


def test_slow_client_gets_the_newest_frames(bridge: BridgeProcess, ros_node: Any,
                                            topic: str) -> None:
    """A Foxglove client that stops reading while 60 camera frames (640x480 rgb8) go through
    the bridge is sent the newest ones when it reads again, not a backlog of all 60: the
    older ones are dropped and it is told so."""
    import json

    from sensor_msgs.msg import Image
    from websockets.sync.client import connect
    from websockets.typing import Subprotocol

    from msgs import cdr
    from msgs.runtime import lookup_message

    image_cls = lookup_message("sensor_msgs/msg/Image")
    pub = ros_node.create_publisher(Image, topic, 10)
    img = Image(height=480, width=640, encoding="rgb8", step=1920, data=bytes(640 * 480 * 3))
    # max_queue=1: the client library itself holds at most one frame it was not asked for
    with connect(bridge.url, subprotocols=[Subprotocol("foxglove.websocket.v1")], max_size=None,
                 max_queue=1, open_timeout=DEADLINE) as ws:
        channel = None
        while channel is None:
            frame = ws.recv(DEADLINE)
            if isinstance(frame, str) and json.loads(frame)["op"] == "advertise":
                channel = next((c for c in json.loads(frame)["channels"]
                                if c["topic"] == topic), None)
        ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 7,
                                                                 "channelId": channel["id"]}]}))
        deadline = time.monotonic() + DEADLINE
        while True:  # one frame through, so the bridge's subscription is matched
            img.header.frame_id = "first"
            pub.publish(img)
            try:
                frame = ws.recv(scenarios.ATTEMPT)
            except TimeoutError:
                assert time.monotonic() < deadline, "no first frame"
                continue
            if isinstance(frame, bytes):
                break
        while True:  # drain what else the first publishes sent
            try:
                ws.recv(1.0)
            except TimeoutError:
                break
        received = _status(bridge)["topics"][topic]["ros_received"]
        for i in range(60):  # the client reads nothing meanwhile
            img.header.frame_id = str(i)
            pub.publish(img)
            wait_until(functools.partial(_bridge_received, bridge, topic, received + i + 1),
                       DEADLINE, f"the bridge to receive frame {i}")
        numbers: list[int] = []
        warnings: list[str] = []
        while not numbers or numbers[-1] != 59:
            frame = ws.recv(DEADLINE)
            if isinstance(frame, bytes):
                assert frame[0] == 1 and int.from_bytes(frame[1:5], "little") == 7
                numbers.append(int(cdr.decode(frame[13:], image_cls)["header"]["frame_id"]))
            elif json.loads(frame)["op"] == "status":
                warnings.append(json.loads(frame)["message"])
    assert numbers == sorted(numbers)
    assert len(numbers) < 45, f"a backlog was sent: {numbers}"
    assert any(f"on {topic}" in w and "dropped" in w for w in warnings), warnings


def _graph_topics(bridge: BridgeProcess) -> list[str]:
    """The topics the bridge's ROS side lists (asked over rosbridge: /rosapi/topics)."""
    from websockets.sync.client import connect

    with connect(bridge.url, open_timeout=DEADLINE) as ws:
        ws.send(json.dumps({"op": "call_service", "service": "/rosapi/topics", "id": "t"}))
        while True:
            reply = json.loads(ws.recv(DEADLINE))
            if reply.get("op") == "service_response":
                return list(reply["values"]["topics"])


def test_time_from_clock(make_bridge: Any, ros_node: Any, topic: str) -> None:
    """With /clock published, the first Foxglove client of a bridge is offered 'time' and
    sent the clock's value."""
    from rosgraph_msgs.msg import Clock  # type: ignore[import-untyped]

    clock = ros_node.create_publisher(Clock, "/clock", 10)
    try:
        bridge = make_bridge()
        wait_until(lambda: "/clock" in _graph_topics(bridge), DEADLINE, "/clock in the graph")
        peer = foxglove_peer(bridge.url, bridge)
        try:
            assert "time" in peer.info["serverInfo"]["capabilities"]
            msg = Clock()
            msg.clock.sec, msg.clock.nanosec = 1234, 5678
            deadline = time.monotonic() + DEADLINE
            event = None
            while event is None and time.monotonic() < deadline:
                clock.publish(msg)
                try:
                    event = peer.wait_event(lambda e: e.get("event") == "time",
                                            scenarios.ATTEMPT, "time")
                except AssertionError:
                    continue
            assert event is not None, peer.diagnostics()
            assert event["timestamp"] == {"$bigint": str(1234 * 10**9 + 5678)}
        finally:
            peer.close()
    finally:
        ros_node.destroy_publisher(clock)


def test_time_only_for_roles_that_may_subscribe_clock(secured: tuple[BridgeProcess, Any],
                                                      ros_node: Any) -> None:
    """With /clock published, a role that may not subscribe to /clock is not offered 'time' and
    gets no tick, while an admin client is offered it and gets the ticks."""
    from rosgraph_msgs.msg import Clock

    clock = ros_node.create_publisher(Clock, "/clock", 10)
    try:
        tester = _as(secured, "tester")  # it may subscribe to anything: it is told of /clock
        try:
            tester.request("wait_channel", topic="/clock", timeout_ms=int(DEADLINE * 1000))
        finally:
            tester.close()
        admin, prober = _as(secured, "admin"), _as(secured, "prober")
        try:
            assert "time" in admin.info["serverInfo"]["capabilities"]
            assert "time" not in prober.info["serverInfo"]["capabilities"]
            msg = Clock()
            msg.clock.sec = 4321
            deadline = time.monotonic() + DEADLINE
            while True:  # until the bridge's /clock reader is matched
                clock.publish(msg)
                try:
                    admin.wait_event(lambda e: e.get("event") == "time", scenarios.ATTEMPT,
                                     "time")
                    break
                except AssertionError:
                    assert time.monotonic() < deadline, admin.diagnostics()
            assert not [e for e in _all_sent(prober) if e.get("event") == "time"]
        finally:
            admin.close()
            prober.close()
    finally:
        ros_node.destroy_publisher(clock)


class _ReloadedRoles:
    """A bridge whose auth file a test rewrites and reloads with SIGHUP: role ``watcher`` (whose
    table the test writes) for principal ``dora``, role ``all`` for ``root``."""

    def __init__(self, directory: Path, watcher: str) -> None:
        from rosbridge_core.security.auth import hash_token, new_token

        self.tokens = {"dora": new_token(), "root": new_token()}
        self.path = directory / "auth.toml"
        self._principals = "".join(
            f'\n[principals.{n}]\nrole = "{"all" if n == "root" else "watcher"}"\n'
            f'token_hash = "{hash_token(t)}"\n' for n, t in self.tokens.items())
        self.write(watcher)
        self.bridge = BridgeProcess(args=["--auth-file", str(self.path)]).start()
        self.peers: list[PeerProcess] = []

    def write(self, watcher: str) -> None:
        """Give role ``watcher`` the table ``watcher`` (TOML lines) in the file."""
        self.path.write_text('[roles.all]\nall = ["*"]\n[roles.watcher]\n' + watcher
                             + self._principals)

    def reload(self, watcher: str) -> str:
        """Write ``watcher``'s table, send the bridge SIGHUP; its reload log line."""
        import signal

        self.write(watcher)
        start = len(self.bridge.lines)
        assert self.bridge.proc is not None
        self.bridge.proc.send_signal(signal.SIGHUP)
        return self.bridge.wait_for_line(r"reloaded the auth file", start=start)

    def connect(self, name: str) -> PeerProcess:
        """A Foxglove client with the token of ``name`` (closed by :meth:`close`)."""
        self.peers.append(foxglove_peer(f"{self.bridge.url}/?token={self.tokens[name]}",
                                        self.bridge))
        return self.peers[-1]

    def close(self) -> None:
        """Close the clients and stop the bridge."""
        for peer in self.peers:
            peer.close()
        self.bridge.stop()


def test_sighup_brings_channels_and_services_to_the_role(tmp_path: Path, ros_node: Any,
                                                         topic: str) -> None:
    """When SIGHUP takes a topic and a service from a role, its Foxglove client is told they
    went (unadvertise, unadvertiseServices); when a later SIGHUP gives them back, they are
    advertised again with the same ids."""
    from std_msgs.msg import String
    from std_srvs.srv import SetBool

    ros_node.create_publisher(String, topic, 10)
    ros_node.create_service(SetBool, topic + "_srv", lambda req, res: res)
    allowed = 'subscribe = ["*"]\ncall_service = ["*"]\n'
    roles = _ReloadedRoles(tmp_path, allowed)
    try:
        dora = roles.connect("dora")
        channel = dora.request("wait_channel", topic=topic, timeout_ms=int(DEADLINE * 1000))
        service = dora.request("service", service=topic + "_srv",
                               timeout_ms=int(DEADLINE * 1000))
        line = roles.reload(allowed + f'deny.subscribe = ["{topic}"]\n'
                            f'deny.call_service = ["{topic}_srv"]\n')
        assert "0 grant(s)" in line  # nothing it held ended: it was only told of them
        dora.wait_event(lambda e: e.get("event") == "unadvertise"
                        and channel["id"] in e["channelIds"], DEADLINE, "unadvertise")
        dora.wait_event(lambda e: e.get("event") == "unadvertiseServices"
                        and service["id"] in e["serviceIds"], DEADLINE, "unadvertiseServices")
        roles.reload(allowed)

        def told(kind: str, key: str, id: int) -> int:
            return sum(1 for e in dora.new_events() if e.get("event") == kind
                       and any(x["id"] == id for x in e[key]))

        wait_until(lambda: told("advertise", "channels", channel["id"]) == 2, DEADLINE,
                   "the channel advertised again")
        wait_until(lambda: told("advertiseServices", "services", service["id"]) == 2,
                   DEADLINE, "the service advertised again")
    finally:
        roles.close()


def test_sighup_ends_time_and_narrows_the_graph(tmp_path: Path, ros_node: Any,
                                                topic: str) -> None:
    """After SIGHUP takes /clock and most introspection from a role, its Foxglove client hears
    that time ended and gets no more ticks (a client of another role still does), and its
    connection graph drops what it may no longer see; when introspection goes too, graph
    updates end. The client hears each."""
    from rosgraph_msgs.msg import Clock
    from std_msgs.msg import String

    clock = ros_node.create_publisher(Clock, "/clock", 10)
    ros_node.create_publisher(String, topic, 10)
    roles = _ReloadedRoles(tmp_path, 'subscribe = ["*"]\nintrospection = ["*"]\n')
    try:
        roles.connect("root").request("wait_channel", topic="/clock",
                                      timeout_ms=int(DEADLINE * 1000))
        dora, root = roles.connect("dora"), roles.connect("root")
        assert "time" in dora.info["serverInfo"]["capabilities"]
        dora.request("subscribe_graph")
        dora.wait_event(_published_by(topic, ros_node.get_fully_qualified_name()), DEADLINE,
                        "the topic in the graph")

        def tick(sec: int) -> None:
            """Publish /clock until root has the tick (so dora's would have been sent too)."""
            msg = Clock()
            msg.clock.sec = sec
            deadline = time.monotonic() + DEADLINE
            while True:
                clock.publish(msg)
                try:
                    root.wait_event(lambda e: e.get("event") == "time" and e["timestamp"] == {
                        "$bigint": str(sec * 10**9)}, scenarios.ATTEMPT, f"tick {sec}")
                    return
                except AssertionError:
                    assert time.monotonic() < deadline, root.diagnostics()

        def ticks(peer: PeerProcess) -> list[int]:
            return [int(e["timestamp"]["$bigint"]) // 10**9 for e in _all_sent(peer)
                    if e.get("event") == "time"]

        tick(1)
        assert 1 in ticks(dora)
        assert "1 grant(s) the new roles no longer allow ended" in roles.reload(
            'subscribe = ["*"]\nintrospection = ["/seen*"]\ndeny.subscribe = ["/clock"]\n')
        _wait_error(dora, "time from /clock ended: role watcher may not subscribe on /clock")
        dora.wait_event(lambda e: e.get("event") == "connectionGraphUpdate"
                        and topic in e["update"]["removedTopics"], DEADLINE,
                        "the topic removed from the graph")
        tick(2)
        assert 2 not in ticks(dora)
        assert "1 grant(s) the new roles no longer allow ended" in roles.reload(
            'subscribe = ["*"]\ndeny.subscribe = ["/clock"]\n')
        _wait_error(dora, "connection graph updates ended: role watcher may not introspection "
                          "on any name")
    finally:
        roles.close()
        ros_node.destroy_publisher(clock)
