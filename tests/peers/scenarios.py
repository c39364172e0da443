"""What a stock client must be able to do through our bridge, with rclpy on the other side.

Each function is one scenario, written once and run against every stock client
(``test_stock.py``, parametrized by the client). ``peer`` is a started
:class:`~tests.peers.peer.PeerProcess`; ``node`` is the test's rclpy node.
Waiting on the ROS graph (a publisher or subscriber being discovered) polls
with a deadline, because discovery has no event; everything else waits on
events: a queue, a reply line, a future's callback.
"""

from __future__ import annotations

import base64
import importlib
import math
import queue
import threading
import time
from typing import Any

from tests.helpers import action_server_answers, wait_until
from tests.peers.peer import PeerError, PeerProcess

#: How long one attempt waits for a message before publishing the next one
#: (messages sent before DDS matched the two ends are lost, so we resend).
ATTEMPT = 0.5
DEADLINE = 15.0

def _module(name: str) -> Any:
    """Import an rclpy module whose API is not fully typed, as Any."""
    return importlib.import_module(name)


def _own_group() -> Any:
    """A callback group for one test's rclpy action end on the module's shared node.

    rclpy leaves a callback group busy for ever when taking from an action client
    or server fails (one destroyed while the executor waits on it), so each action
    end gets a group of its own: the node's default group, which every later test
    uses, is never stuck by it.
    """
    return _module("rclpy.callback_groups").MutuallyExclusiveCallbackGroup()


def _refusal(peer: PeerProcess, topic: str) -> None:
    """Fail at once if the bridge sent an error status about ``topic`` (clients that show them)."""
    for e in peer.new_events():
        about_topic = str(e.get("id") or "").split(":")[1:2] == [topic]  # "op:topic:n"
        if e.get("event") == "status" and about_topic and e["msg"].get("level") == "error":
            raise AssertionError(f"the bridge refused a request about {topic}: {e['msg']}")


def _publish_until_received(
    peer: PeerProcess, topic: str, type_name: str, msg: dict[str, Any], inbox: queue.Queue[Any]
) -> Any:
    """Publish ``msg`` through the peer until the rclpy subscription's inbox gets one."""
    for _ in range(int(DEADLINE / ATTEMPT)):
        _refusal(peer, topic)
        peer.request("publish", topic=topic, type=type_name, msg=msg)
        try:
            return inbox.get(timeout=ATTEMPT)
        except queue.Empty:
            continue
    raise AssertionError(
        f"rclpy never received what {peer.name} published on {topic}\n{peer.diagnostics()}"
    )


def _ros_publish_until_delivered(peer: PeerProcess, pub: Any, topic: str, msg: Any) -> Any:
    """Publish ``msg`` from rclpy until the peer prints a message event for ``topic``."""
    for _ in range(int(DEADLINE / ATTEMPT)):
        _refusal(peer, topic)
        pub.publish(msg)
        try:
            return peer.wait_event(
                lambda e: e.get("event") == "message" and e.get("topic") == topic,
                ATTEMPT, f"message on {topic}",
            )["msg"]
        except AssertionError:
            continue
    raise AssertionError(f"{peer.name} never got a message on {topic}\n{peer.diagnostics()}")


def _call_new_service(peer: PeerProcess, service: str, args: dict[str, Any]) -> Any:
    """Call a service the test has just created, once the bridge has discovered it.

    The bridge waits a moment for a service it does not know yet; on a loaded
    machine discovery can take longer, and the bridge then answers "does not
    exist". That is graph discovery, so it is retried (with a deadline); any
    other failure is reported at once.
    """
    deadline = time.monotonic() + DEADLINE
    while True:
        try:
            return peer.request("call", service=service, args=args)
        except PeerError as exc:
            if "does not exist" not in str(exc) or time.monotonic() > deadline:
                raise


def _call_from_ros(node: Any, srv_type: Any, name: str, request: Any) -> Any:
    """Call service ``name`` from an rclpy client and return the response (with deadlines)."""
    client = node.create_client(srv_type, name)
    try:
        assert client.wait_for_service(timeout_sec=DEADLINE), f"{name} never appeared in the graph"
        done = threading.Event()
        future = client.call_async(request)
        future.add_done_callback(lambda _f: done.set())
        assert done.wait(DEADLINE), f"no response from {name} within {DEADLINE} s"
        return future.result()
    finally:
        node.destroy_client(client)


# -- topics -----------------------------------------------------------------------------------


def publish_string(peer: PeerProcess, node: Any, topic: str, type_name: str) -> None:
    """The peer advertises and publishes a std_msgs/String; an rclpy subscriber gets it."""
    from std_msgs.msg import String

    inbox: queue.Queue[Any] = queue.Queue()
    node.create_subscription(String, topic, inbox.put, 10)
    peer.request("advertise", topic=topic, type=type_name)
    wait_until(lambda: node.count_publishers(topic) >= 1, DEADLINE, f"bridge publisher on {topic}")
    text = f"hello from {peer.name} \u00e9\u4e16"
    got = _publish_until_received(peer, topic, type_name, {"data": text}, inbox)
    assert got.data == text


def publish_nested(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer publishes a geometry_msgs/Twist (nested float fields); rclpy sees the values."""
    from geometry_msgs.msg import Twist

    inbox: queue.Queue[Any] = queue.Queue()
    node.create_subscription(Twist, topic, inbox.put, 10)
    peer.request("advertise", topic=topic, type="geometry_msgs/Twist")
    wait_until(lambda: node.count_publishers(topic) >= 1, DEADLINE, f"bridge publisher on {topic}")
    msg = {"linear": {"x": 0.5, "y": -1.25, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 3}}
    got = _publish_until_received(peer, topic, "geometry_msgs/Twist", msg, inbox)
    assert (got.linear.x, got.linear.y, got.linear.z) == (0.5, -1.25, 0.0)
    assert (got.angular.x, got.angular.y, got.angular.z) == (0.0, 0.0, 3.0)


def subscribe_string(peer: PeerProcess, node: Any, topic: str, type_name: str) -> None:
    """The peer subscribes; an rclpy publisher's std_msgs/String reaches it unchanged."""
    from std_msgs.msg import String

    pub = node.create_publisher(String, topic, 10)
    peer.request("subscribe", topic=topic, type=type_name)
    wait_until(lambda: pub.get_subscription_count() >= 1, DEADLINE, f"bridge subscriber on {topic}")
    text = f"hello to {peer.name} \u00e9\u4e16"
    got = _ros_publish_until_delivered(peer, pub, topic, String(data=text))
    assert got == {"data": text}


def subscribe_nested(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer gets a sensor_msgs/CompressedImage: header stamp as sec/nanosec, uint8[] as base64."""
    from sensor_msgs.msg import CompressedImage

    pub = node.create_publisher(CompressedImage, topic, 10)
    peer.request("subscribe", topic=topic, type="sensor_msgs/msg/CompressedImage")
    wait_until(lambda: pub.get_subscription_count() >= 1, DEADLINE, f"bridge subscriber on {topic}")
    payload = bytes([0, 1, 2, 127, 128, 254, 255])
    msg = CompressedImage(format="png", data=payload)
    msg.header.frame_id = "camera"
    msg.header.stamp.sec = 1_700_000_000
    msg.header.stamp.nanosec = 123_456_789
    got = _ros_publish_until_delivered(peer, pub, topic, msg)
    assert got == {
        "header": {"stamp": {"sec": 1_700_000_000, "nanosec": 123_456_789}, "frame_id": "camera"},
        "format": "png",
        "data": base64.b64encode(payload).decode("ascii"),
    }


# -- services ---------------------------------------------------------------------------------


def call_setbool(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer calls an rclpy std_srvs/SetBool service (no type given) and gets its answer."""
    from std_srvs.srv import SetBool

    seen: list[bool] = []

    def serve(request: Any, response: Any) -> Any:
        seen.append(request.data)
        response.success = not request.data
        response.message = f"rclpy got data={request.data}"
        return response

    node.create_service(SetBool, topic, serve)
    assert _call_new_service(peer, topic, {"data": True}) == {
        "success": False, "message": "rclpy got data=True",
    }
    assert peer.request("call", service=topic, args={"data": False}) == {
        "success": True, "message": "rclpy got data=False",
    }
    assert seen == [True, False]


def call_mult(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer calls an rclpy mult_msgs/MultFloats service and gets the product back."""
    from mult_msgs.srv import MultFloats

    def serve(request: Any, response: Any) -> Any:
        response.result = request.x * request.y
        return response

    node.create_service(MultFloats, topic, serve)
    assert _call_new_service(peer, topic, {"x": 2.5, "y": -4.0}) == {"result": -10.0}


def call_missing(peer: PeerProcess, topic: str) -> None:
    """Calling a service nobody offers fails promptly through the client's error path."""
    missing = topic + "_nobody_serves_this"
    try:
        value = peer.request("call", service=missing, args={}, timeout=20.0)
    except PeerError as exc:
        text = str(exc)
        assert "Timeout" not in text, f"the client timed out instead of being told: {text}"
        assert missing in text, f"the error does not name the service: {text}"
    else:
        raise AssertionError(f"call to {missing} succeeded with {value!r}")


def serve_setbool(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer serves std_srvs/SetBool; an rclpy client's calls reach it and get its answers."""
    from std_srvs.srv import SetBool

    peer.request("advertise_service", service=topic, type="std_srvs/srv/SetBool", handler="setbool")
    client_name = "roslibpy" if peer.name.startswith("roslibpy") else "roslibjs"
    for data in (True, False):
        response = _call_from_ros(node, SetBool, topic, SetBool.Request(data=data))
        assert response.success is data
        assert response.message == f"{client_name} got data={data}"
    requests = [e for e in peer.new_events() if e.get("event") == "request" and e["service"] == topic]
    assert [e["args"] for e in requests] == [{"data": True}, {"data": False}]


def serve_mult(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer serves mult_msgs/MultFloats (short type spelling); an rclpy client gets x*y."""
    from mult_msgs.srv import MultFloats

    peer.request("advertise_service", service=topic, type="mult_msgs/MultFloats", handler="mult")
    response = _call_from_ros(node, MultFloats, topic, MultFloats.Request(x=1.5, y=6.0))
    assert response.result == 9.0


def unadvertise_service(peer: PeerProcess, node: Any, topic: str) -> None:
    """After the peer unadvertises its service, it leaves the ROS graph."""
    from std_srvs.srv import SetBool

    peer.request("advertise_service", service=topic, type="std_srvs/srv/SetBool", handler="setbool")
    response = _call_from_ros(node, SetBool, topic, SetBool.Request(data=True))
    assert response.success is True
    peer.request("unadvertise_service", service=topic)

    def gone() -> bool:
        names = {name for name, _types in node.get_service_names_and_types()}
        return topic not in names

    wait_until(gone, DEADLINE, f"{topic} to leave the graph")


# -- rosapi (introspection) -------------------------------------------------------------------


def _topics(value: Any) -> tuple[list[str], list[str] | None]:
    """roslibpy returns the topic list; roslib returns {topics, types}."""
    if isinstance(value, dict):
        return list(value["topics"]), list(value["types"])
    return list(value), None


def get_topics(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer's topic list names an rclpy publisher's topic (with its type where given)."""
    from std_msgs.msg import String

    node.create_publisher(String, topic, 10)

    def listed() -> Any:
        topics, types = _topics(peer.request("get_topics"))
        return (topics, types) if topic in topics else None

    topics, types = wait_until(listed, DEADLINE, f"{topic} in get_topics")
    if types is not None:  # roslib: the rosapi answer as is, types alongside
        assert len(types) == len(topics)
        assert types[topics.index(topic)] == "std_msgs/msg/String"
    else:  # roslibpy returns the names only; its way to the type is get_topic_type
        assert peer.request("get_topic_type", topic=topic) == "std_msgs/msg/String"


def get_topic_type(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer learns an rclpy topic's type, and the topics of that type include it."""
    from std_msgs.msg import String

    node.create_publisher(String, topic, 10)
    wait_until(lambda: peer.request("get_topic_type", topic=topic), DEADLINE, f"type of {topic}")
    assert peer.request("get_topic_type", topic=topic) == "std_msgs/msg/String"
    assert topic in peer.request("get_topics_for_type", type="std_msgs/msg/String")


def get_services(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer's service list names an rclpy service; its type and same-type list agree."""
    from std_srvs.srv import SetBool

    node.create_service(SetBool, topic, lambda _req, resp: resp)
    wait_until(lambda: topic in peer.request("get_services"), DEADLINE, f"{topic} in get_services")
    assert peer.request("get_service_type", service=topic) == "std_srvs/srv/SetBool"
    assert topic in peer.request("get_services_for_type", type="std_srvs/srv/SetBool")


def get_nodes(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer's node list names the rclpy node; its details list what it publishes and serves."""
    from std_msgs.msg import String
    from std_srvs.srv import SetBool

    node.create_publisher(String, topic, 10)
    node.create_service(SetBool, topic + "_srv", lambda _req, resp: resp)
    fqn = node.get_fully_qualified_name()
    wait_until(lambda: fqn in peer.request("get_nodes"), DEADLINE, f"{fqn} in get_nodes")

    def detailed() -> Any:
        details = peer.request("get_node_details", node=fqn)
        ok = topic in details["publishing"] and topic + "_srv" in details["services"]
        return details if ok else None

    wait_until(detailed, DEADLINE, f"{topic} and {topic}_srv in node details of {fqn}")


# -- more topic behaviour ---------------------------------------------------------------------


def unsubscribe(peer: PeerProcess, node: Any, topic: str) -> None:
    """After the peer unsubscribes, the bridge drops its ROS subscription."""
    from std_msgs.msg import String

    pub = node.create_publisher(String, topic, 10)
    peer.request("subscribe", topic=topic, type="std_msgs/msg/String")
    wait_until(lambda: pub.get_subscription_count() >= 1, DEADLINE, f"bridge subscriber on {topic}")
    _ros_publish_until_delivered(peer, pub, topic, String(data="before"))
    peer.request("unsubscribe", topic=topic, type="std_msgs/msg/String")
    wait_until(lambda: pub.get_subscription_count() == 0, DEADLINE, "the bridge subscription to go")


def unadvertise(peer: PeerProcess, node: Any, topic: str) -> None:
    """After the peer unadvertises, the bridge's ROS publisher leaves the graph."""
    peer.request("advertise", topic=topic, type="std_msgs/String")
    wait_until(lambda: node.count_publishers(topic) >= 1, DEADLINE, f"bridge publisher on {topic}")
    peer.request("unadvertise", topic=topic, type="std_msgs/String")
    wait_until(lambda: node.count_publishers(topic) == 0, DEADLINE, "the bridge publisher to go")


def _latched_qos() -> Any:
    qos = _module("rclpy.qos")
    return qos.QoSProfile(
        depth=1,
        durability=qos.DurabilityPolicy.TRANSIENT_LOCAL,
        reliability=qos.ReliabilityPolicy.RELIABLE,
    )


def publish_latched(peer: PeerProcess, node: Any, topic: str) -> None:
    """A latched publish from the peer reaches a transient-local rclpy subscriber that joins later."""
    from std_msgs.msg import String

    peer.request("publish", topic=topic, type="std_msgs/String", msg={"data": "latched"}, latch=True)
    # A round trip on the same connection: the bridge has handled the publish before it answers.
    peer.request("get_topic_type", topic=topic)
    inbox: queue.Queue[Any] = queue.Queue()
    node.create_subscription(String, topic, inbox.put, _latched_qos())
    try:
        got = inbox.get(timeout=DEADLINE)
    except queue.Empty:
        raise AssertionError(
            f"a late transient-local subscriber never got the latched message\n{peer.diagnostics()}"
        ) from None
    assert got.data == "latched"


def subscribe_latched(peer: PeerProcess, node: Any, topic: str) -> None:
    """A peer subscribing late still gets the last message of a transient-local rclpy publisher."""
    from std_msgs.msg import String

    pub = node.create_publisher(String, topic, _latched_qos())
    pub.publish(String(data="the map"))
    peer.request("subscribe", topic=topic, type="std_msgs/msg/String")
    got = peer.wait_event(
        lambda e: e.get("event") == "message" and e.get("topic") == topic, DEADLINE,
        f"the latched message on {topic}",
    )
    assert got["msg"] == {"data": "the map"}


def bad_type_then_publish(peer: PeerProcess, node: Any, topic: str, sees_status: bool) -> None:
    """An unknown type is refused, and the same connection goes on publishing normally."""
    peer.request("publish", topic=topic + "_bad", type="nope_msgs/Nope", msg={"data": 1})
    if sees_status:
        status = peer.wait_event(
            lambda e: e.get("event") == "status" and e.get("about") == "advertise", DEADLINE,
            "a status about the refused advertise",
        )["msg"]
        assert status["level"] == "error"
        assert "nope_msgs/Nope" in status["msg"], status
    publish_string(peer, node, topic, "std_msgs/String")


# -- between two stock clients ----------------------------------------------------------------


def client_to_client_topic(
    sender: PeerProcess, receiver: PeerProcess, node: Any, topic: str
) -> None:
    """What one stock client publishes, another stock client on the same bridge receives."""
    type_name = "std_msgs/String"
    receiver.request("subscribe", topic=topic, type=type_name)
    wait_until(lambda: node.count_subscribers(topic) >= 1, DEADLINE, f"bridge subscriber on {topic}")
    sender.request("advertise", topic=topic, type=type_name)
    wait_until(lambda: node.count_publishers(topic) >= 1, DEADLINE, f"bridge publisher on {topic}")
    text = f"from {sender.name} to {receiver.name}"
    for _ in range(int(DEADLINE / ATTEMPT)):
        sender.request("publish", topic=topic, type=type_name, msg={"data": text})
        try:
            got = receiver.wait_event(
                lambda e: e.get("event") == "message" and e.get("topic") == topic, ATTEMPT
            )
        except AssertionError:
            continue
        assert got["msg"] == {"data": text}
        return
    raise AssertionError(f"{receiver.name} never got {sender.name}'s message\n{receiver.diagnostics()}")


def client_to_client_service(
    server: PeerProcess, caller: PeerProcess, node: Any, topic: str
) -> None:
    """A service one stock client serves answers another stock client's call."""
    server.request("advertise_service", service=topic, type="mult_msgs/srv/MultFloats", handler="mult")

    def listed() -> bool:
        return topic in {name for name, _types in node.get_service_names_and_types()}

    wait_until(listed, DEADLINE, f"{topic} in the ROS graph")
    assert _call_new_service(caller, topic, {"x": 3.0, "y": 0.5}) == {"result": 1.5}
    assert server.wait_event(lambda e: e.get("event") == "request" and e["service"] == topic)[
        "args"
    ] == {"x": 3.0, "y": 0.5}


# -- CBOR (roslib decodes it) -----------------------------------------------------------------


def _plain(value: Any) -> Any:
    """Undo the driver's tagging of typed arrays, recursively."""
    if isinstance(value, dict):
        if set(value) == {"$typed", "values"}:
            return list(value["values"])
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_plain(v) for v in value]
    return value


def subscribe_cbor(peer: PeerProcess, node: Any, topic: str) -> None:
    """With compression cbor, float64[] arrive as Float64Array and uint8[] as Uint8Array."""
    from sensor_msgs.msg import JointState

    pub = node.create_publisher(JointState, topic, 10)
    peer.request("subscribe", topic=topic, type="sensor_msgs/msg/JointState", compression="cbor")
    wait_until(lambda: pub.get_subscription_count() >= 1, DEADLINE, f"bridge subscriber on {topic}")
    msg = JointState(name=["elbow", "wrist"], position=[1.5, -2.25], velocity=[], effort=[0.5, 1e300])
    msg.header.stamp.sec = 7
    msg.header.stamp.nanosec = 8
    msg.header.frame_id = "arm"
    got = _ros_publish_until_delivered(peer, pub, topic, msg)
    assert got["position"] == {"$typed": "Float64Array", "values": [1.5, -2.25]}
    assert got["effort"] == {"$typed": "Float64Array", "values": [0.5, 1e300]}
    assert _plain(got) == {
        "header": {"stamp": {"sec": 7, "nanosec": 8}, "frame_id": "arm"},
        "name": ["elbow", "wrist"],
        "position": [1.5, -2.25],
        "velocity": [],
        "effort": [0.5, 1e300],
    }


def subscribe_cbor_bytes(peer: PeerProcess, node: Any, topic: str) -> None:
    """With compression cbor, a uint8[] field arrives as a Uint8Array of the same bytes."""
    from sensor_msgs.msg import CompressedImage

    pub = node.create_publisher(CompressedImage, topic, 10)
    peer.request(
        "subscribe", topic=topic, type="sensor_msgs/msg/CompressedImage", compression="cbor"
    )
    wait_until(lambda: pub.get_subscription_count() >= 1, DEADLINE, f"bridge subscriber on {topic}")
    payload = bytes(range(256)) * 4
    got = _ros_publish_until_delivered(peer, pub, topic, CompressedImage(format="jpeg", data=payload))
    assert got["data"] == {"$typed": "Uint8Array", "values": list(payload)}
    assert got["format"] == "jpeg"


def subscribe_cbor_raw(peer: PeerProcess, node: Any, topic: str) -> None:
    """With compression cbor-raw, the client gets the CDR bytes, which rclpy deserializes back."""
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import JointState

    pub = node.create_publisher(JointState, topic, 10)
    peer.request(
        "subscribe", topic=topic, type="sensor_msgs/msg/JointState", compression="cbor-raw"
    )
    wait_until(lambda: pub.get_subscription_count() >= 1, DEADLINE, f"bridge subscriber on {topic}")
    msg = JointState(name=["a"], position=[0.125], velocity=[2.0], effort=[])
    got = _ros_publish_until_delivered(peer, pub, topic, msg)
    assert isinstance(got["secs"], int) and isinstance(got["nsecs"], int), got
    assert got["bytes"]["$typed"] == "Uint8Array"
    back = deserialize_message(bytes(got["bytes"]["values"]), JointState)
    assert back == msg


#: (message type, values, the typed array a CBOR decoder must make of them)
CBOR_ARRAYS = [
    ("std_msgs/msg/Float32MultiArray", [0.5, -1.25, 2.0**100], "Float32Array"),  # exact in f32
    ("std_msgs/msg/Int8MultiArray", [-128, 0, 127], "Int8Array"),
    ("std_msgs/msg/UInt16MultiArray", [0, 1, 65535], "Uint16Array"),
    ("std_msgs/msg/Int32MultiArray", [-(2**31), 7, 2**31 - 1], "Int32Array"),
    ("std_msgs/msg/UInt32MultiArray", [0, 2**32 - 1], "Uint32Array"),
    ("std_msgs/msg/Int64MultiArray", [-(2**63), 0, 2**63 - 1], "BigInt64Array"),
    ("std_msgs/msg/UInt64MultiArray", [0, 2**64 - 1], "BigUint64Array"),
]


def subscribe_cbor_typed_array(
    peer: PeerProcess, node: Any, topic: str, type_name: str, values: list[Any], typed: str
) -> None:
    """With compression cbor, a numeric array arrives as the matching JavaScript typed array."""
    pkg, _, name = type_name.split("/")
    msg_cls = getattr(importlib.import_module(f"{pkg}.msg"), name)
    pub = node.create_publisher(msg_cls, topic, 10)
    peer.request("subscribe", topic=topic, type=type_name, compression="cbor")
    got = _ros_publish_until_delivered(peer, pub, topic, msg_cls(data=values))
    expected = [str(v) for v in values] if typed.startswith("Big") else values
    assert got["data"] == {"$typed": typed, "values": expected}


# -- parameters and type details through rosapi -----------------------------------------------


def params(peer: PeerProcess, node: Any) -> None:
    """The peer lists, reads and sets an rclpy node's parameter as "node:param"."""
    param = f"speed_{peer.name.replace('-', '_')}"  # the node is shared by a module's tests
    node.declare_parameter(param, 1.5)
    name = f"{node.get_fully_qualified_name()}:{param}"
    wait_until(lambda: name in peer.request("get_params"), DEADLINE, f"{name} in get_params")
    assert peer.request("get_param", name=name) == 1.5
    peer.request("set_param", name=name, value=2.5)
    assert node.get_parameter(param).value == 2.5
    assert peer.request("get_param", name=name) == 2.5


FOXGLOVE_PARAMETERS: list[tuple[str, Any, dict[str, Any]]] = [
    ("flag", True, {"value": True}),
    ("count", 7, {"value": 7}),
    ("gain", 1.5, {"value": 1.5, "type": "float64"}),
    ("whole", 2.0, {"value": 2.0, "type": "float64"}),
    ("label", "hi", {"value": "hi"}),
    ("blob", [b"\x00", b"\xff", b"h"], {"value": "AP9o", "type": "byte_array"}),
    ("flags", [True, False], {"value": [True, False]}),
    ("counts", [1, 2], {"value": [1, 2]}),
    ("gains", [1.5, 2.0], {"value": [1.5, 2.0], "type": "float64_array"}),
    ("labels", ["a", "b"], {"value": ["a", "b"]}),
    ("odd", math.inf, {"value": "inf"}),
    ("odds", [1.0, math.nan], {"value": [1.0, "nan"]}),
]
"""A parameter of each ROS 2 type (name, the value rclpy declares, the ``parameterValues``
entry a Foxglove client must get for it, name left out): ws-protocol's spec types a byte
array ``byte_array`` (base64 text), a double ``float64``, a double array ``float64_array``;
JSON has no NaN or infinity, so one is its text, untyped."""


def declare_foxglove_parameters(node: Any, prefix: str) -> list[tuple[str, dict[str, Any]]]:
    """Declare :data:`FOXGLOVE_PARAMETERS` on ``node`` as ``prefix`` + name; each one's
    Foxglove name (``/node.param``) and the entry a client must get for it."""
    full = node.get_fully_qualified_name()
    for name, value, _ in FOXGLOVE_PARAMETERS:
        node.declare_parameter(prefix + name, value)
    return [(f"{full}.{prefix}{name}", {"name": f"{full}.{prefix}{name}", **entry})
            for name, _, entry in FOXGLOVE_PARAMETERS]


def message_details(peer: PeerProcess) -> None:
    """The peer gets rosapi typedefs for geometry_msgs/Twist, nested Vector3 included."""
    value = peer.request("get_message_details", type="geometry_msgs/Twist")
    typedefs = value["typedefs"]
    assert typedefs[0]["type"].replace("/msg/", "/") == "geometry_msgs/Twist", "root type first"
    # rosapi on ROS 2 names primitives the IDL way ("double", "boolean"); ROS 1 said
    # "float64", "bool". Either is accepted here.
    f64 = typedefs[-1]["fieldtypes"][0]
    assert f64 in ("float64", "double"), typedefs
    if "decoded" in value:  # roslib's Ros.decodeTypeDefs walked them
        vector = {"x": f64, "y": f64, "z": f64}
        assert value["problems"] == []
        assert value["decoded"] == {"linear": vector, "angular": vector}
    by_type = {td["type"].replace("/msg/", "/"): td for td in typedefs}
    twist = by_type["geometry_msgs/Twist"]
    assert twist["fieldnames"] == ["linear", "angular"]
    assert [t.replace("/msg/", "/") for t in twist["fieldtypes"]] == ["geometry_msgs/Vector3"] * 2
    vector = by_type["geometry_msgs/Vector3"]
    assert vector["fieldnames"] == ["x", "y", "z"]
    assert vector["fieldtypes"] == [f64] * 3


def service_details(peer: PeerProcess) -> None:
    """The peer gets typedefs for the request and the response part of std_srvs/SetBool."""
    request = peer.request("get_service_request_details", type="std_srvs/srv/SetBool")
    response = peer.request("get_service_response_details", type="std_srvs/srv/SetBool")
    req_def, resp_def = request["typedefs"][0], response["typedefs"][0]
    boolean = req_def["fieldtypes"][0]
    assert boolean in ("bool", "boolean"), req_def  # ROS 1 / ROS 2 (IDL) spelling
    assert (req_def["fieldnames"], req_def["fieldtypes"]) == (["data"], [boolean])
    assert (resp_def["fieldnames"], resp_def["fieldtypes"]) == (
        ["success", "message"], [boolean, "string"],
    )


def topics_and_raw_types(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer gets each topic with its type and the type's full definition text."""
    from std_msgs.msg import String

    node.create_publisher(String, topic, 10)

    def listed() -> Any:
        value = peer.request("get_topics_and_raw_types")
        return value if topic in value["topics"] else None

    value = wait_until(listed, DEADLINE, f"{topic} in topics_and_raw_types")
    i = value["topics"].index(topic)
    assert len(value["topics"]) == len(value["types"]) == len(value["typedefs_full_text"])
    assert value["types"][i] == "std_msgs/msg/String"
    assert "string data" in value["typedefs_full_text"][i]


# -- actions ----------------------------------------------------------------------------------


def _wait_future(future: Any, what: str) -> Any:
    done = threading.Event()
    future.add_done_callback(lambda _f: done.set())
    assert done.wait(DEADLINE), f"no {what} within {DEADLINE} s"
    return future.result()


def send_goal(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer sends a Fibonacci goal to an rclpy action server and gets the result."""
    from test_msgs.action import Fibonacci

    def execute(goal_handle: Any) -> Any:
        sequence = [0, 1]
        for i in range(1, goal_handle.request.order):
            sequence.append(sequence[i] + sequence[i - 1])
            goal_handle.publish_feedback(Fibonacci.Feedback(sequence=sequence))
        goal_handle.succeed()
        return Fibonacci.Result(sequence=sequence)

    server = _module("rclpy.action").ActionServer(
        node, Fibonacci, topic, execute, callback_group=_own_group()
    )
    try:
        value = peer.request(
            "send_goal", action=topic, type="test_msgs/action/Fibonacci", goal={"order": 5},
            goal_timeout=5.0, timeout=DEADLINE,
        )
    finally:
        server.destroy()
    assert value["status"] == 4  # SUCCEEDED
    assert value["values"]["sequence"] == [0, 1, 1, 2, 3, 5]
    for fb in value["feedback"]:
        assert fb["sequence"] == [0, 1, 1, 2, 3, 5][: len(fb["sequence"])]


def serve_action(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer serves a Fibonacci action; an rclpy action client gets feedback and the result."""
    from action_msgs.msg import GoalStatus
    from test_msgs.action import Fibonacci

    peer.request(
        "advertise_action", action=topic, type="test_msgs/action/Fibonacci", handler="fibonacci"
    )
    client = _module("rclpy.action").ActionClient(
        node, Fibonacci, topic, callback_group=_own_group()
    )
    answers = action_server_answers(client)
    try:

        def ready_or_refused() -> Any:
            refused = [e for e in peer.new_events() if e.get("event") == "status"]
            return refused or answers()

        outcome = wait_until(ready_or_refused, DEADLINE, f"{topic} action server in the graph")
        assert outcome is True, f"the bridge refused advertise_action: {outcome}"
        handle = _wait_future(client.send_goal_async(Fibonacci.Goal(order=5)), "goal acceptance")
        assert handle.accepted
        result = _wait_future(handle.get_result_async(), "action result")
    finally:
        client.destroy()
    assert result.status == GoalStatus.STATUS_SUCCEEDED
    assert list(result.result.sequence) == [0, 1, 1, 2, 3, 5]


def serve_action_canceled(peer: PeerProcess, node: Any, topic: str) -> None:
    """An rclpy client cancels a goal the peer serves; the peer's cancel handler ends it canceled."""
    from action_msgs.msg import GoalStatus
    from test_msgs.action import Fibonacci

    peer.request(
        "advertise_action", action=topic, type="test_msgs/action/Fibonacci",
        handler="until_canceled",
    )
    client = _module("rclpy.action").ActionClient(
        node, Fibonacci, topic, callback_group=_own_group()
    )
    first_feedback = threading.Event()
    try:
        wait_until(action_server_answers(client), DEADLINE, f"{topic} action server answering")
        goal = client.send_goal_async(
            Fibonacci.Goal(order=3), feedback_callback=lambda _msg: first_feedback.set()
        )
        handle = _wait_future(goal, "goal acceptance")
        assert handle.accepted
        result_future = handle.get_result_async()
        assert first_feedback.wait(DEADLINE), "no feedback from the peer"
        _wait_future(handle.cancel_goal_async(), "cancel answer")
        result = _wait_future(result_future, "action result")
    finally:
        client.destroy()
    assert result.status == GoalStatus.STATUS_CANCELED
    assert list(result.result.sequence) == [0, 1]


# -- robustness through stock clients ---------------------------------------------------------


def publish_ros1_time_keys(peer: PeerProcess, node: Any, topic: str) -> None:
    """roslibpy.ros2.Header writes the stamp as secs/nsecs; rclpy gets the same time."""
    from geometry_msgs.msg import PoseStamped

    inbox: queue.Queue[Any] = queue.Queue()
    node.create_subscription(PoseStamped, topic, inbox.put, 10)
    peer.request("advertise", topic=topic, type="geometry_msgs/PoseStamped")
    wait_until(lambda: node.count_publishers(topic) >= 1, DEADLINE, f"bridge publisher on {topic}")
    msg = {
        "header": {"stamp": {"secs": 1_700_000_001, "nsecs": 5}, "frame_id": "map"},
        "pose": {"position": {"x": 1.0, "y": 2.0, "z": 0.0}, "orientation": {"w": 1.0}},
    }
    for _ in range(int(DEADLINE / ATTEMPT)):
        peer.request("publish", topic=topic, type="geometry_msgs/PoseStamped", msg=msg,
                     ros2_header=True)
        try:
            got = inbox.get(timeout=ATTEMPT)
            break
        except queue.Empty:
            continue
    else:
        raise AssertionError(f"rclpy never received the PoseStamped\n{peer.diagnostics()}")
    assert (got.header.stamp.sec, got.header.stamp.nanosec) == (1_700_000_001, 5)
    assert got.header.frame_id == "map"
    assert (got.pose.position.x, got.pose.position.y, got.pose.orientation.w) == (1.0, 2.0, 1.0)


def burst_in_order(peer: PeerProcess, node: Any, topic: str) -> None:
    """100 messages published back to back reach a reliable rclpy subscriber, all and in order."""
    from std_msgs.msg import Int32

    inbox: queue.Queue[Any] = queue.Queue()
    node.create_subscription(Int32, topic, inbox.put, _module("rclpy.qos").QoSProfile(depth=1000))
    peer.request("advertise", topic=topic, type="std_msgs/Int32", queue_size=100)
    wait_until(lambda: node.count_publishers(topic) >= 1, DEADLINE, f"bridge publisher on {topic}")
    _publish_until_received(peer, topic, "std_msgs/Int32", {"data": -1}, inbox)
    while not inbox.empty():  # later copies of the warm-up message
        inbox.get_nowait()
    seqs = [peer.send("publish", topic=topic, type="std_msgs/Int32", msg={"data": i})
            for i in range(100)]
    for seq in seqs:
        assert peer.reply(seq)["ok"]
    got: list[int] = []
    while len(got) < 100:
        try:
            data = inbox.get(timeout=DEADLINE).data
        except queue.Empty:
            raise AssertionError(f"only {len(got)} of 100 arrived: {got[-5:]}") from None
        if data != -1:
            got.append(data)
    assert got == list(range(100))


def killed_client_service_goes(peer: PeerProcess, node: Any, topic: str) -> None:
    """When a client serving a service is killed, its service leaves the ROS graph."""
    peer.request("advertise_service", service=topic, type="std_srvs/srv/SetBool", handler="setbool")

    def listed() -> bool:
        return topic in {name for name, _types in node.get_service_names_and_types()}

    wait_until(listed, DEADLINE, f"{topic} in the ROS graph")
    assert peer.proc is not None
    peer.proc.kill()
    peer.proc.wait(DEADLINE)
    wait_until(lambda: not listed(), DEADLINE, f"{topic} to leave the graph after the kill")


def failing_handler(peer: PeerProcess, node: Any, topic: str) -> None:
    """When the client's service handler reports failure, the rclpy caller gets no invented answer."""
    from std_srvs.srv import SetBool

    peer.request("advertise_service", service=topic, type="std_srvs/srv/SetBool", handler="fail")
    client = node.create_client(SetBool, topic)
    try:
        assert client.wait_for_service(timeout_sec=DEADLINE), f"{topic} never appeared"
        future = client.call_async(SetBool.Request(data=True))
        peer.wait_event(lambda e: e.get("event") == "request" and e.get("service") == topic,
                        DEADLINE, "the request")
        # The peer answered result false before it handles this command, and the bridge
        # handles the peer's ops in order: the failure has been dealt with by now.
        peer.request("get_topic_type", topic="/rosout")
        assert not future.done()  # a ROS service cannot send an error; no default either
    finally:
        node.destroy_client(client)


def publish_large(peer: PeerProcess, node: Any, topic: str) -> None:
    """A 1.5 MB sensor_msgs/Image (base64 data) published by the client reaches rclpy intact."""
    from sensor_msgs.msg import Image

    inbox: queue.Queue[Any] = queue.Queue()
    node.create_subscription(Image, topic, inbox.put, 10)
    peer.request("advertise", topic=topic, type="sensor_msgs/msg/Image")
    wait_until(lambda: node.count_publishers(topic) >= 1, DEADLINE, f"bridge publisher on {topic}")
    width, height = 800, 640
    pixels = bytes((i * 7) % 251 for i in range(width * height * 3))
    msg = {"height": height, "width": width, "encoding": "rgb8", "step": width * 3,
           "data": base64.b64encode(pixels).decode("ascii")}
    got = _publish_until_received(peer, topic, "sensor_msgs/msg/Image", msg, inbox)
    assert (got.width, got.height, got.encoding) == (width, height, "rgb8")
    assert bytes(got.data) == pixels


def subscribe_large(peer: PeerProcess, node: Any, topic: str) -> None:
    """A 1.5 MB sensor_msgs/Image from rclpy reaches the client, data as base64."""
    from sensor_msgs.msg import Image

    pub = node.create_publisher(Image, topic, 10)
    peer.request("subscribe", topic=topic, type="sensor_msgs/msg/Image")
    wait_until(lambda: pub.get_subscription_count() >= 1, DEADLINE, f"bridge subscriber on {topic}")
    width, height = 800, 640
    pixels = bytes((i * 13) % 251 for i in range(width * height * 3))
    msg = Image(height=height, width=width, encoding="rgb8", step=width * 3, data=pixels)
    got = _ros_publish_until_delivered(peer, pub, topic, msg)
    assert (got["width"], got["height"], got["encoding"]) == (width, height, "rgb8")
    assert base64.b64decode(got["data"]) == pixels


def call_timeout(peer: PeerProcess, node: Any, topic: str) -> None:
    """A call with roslib's timeout argument fails promptly when the rclpy service is too slow."""
    from std_srvs.srv import SetBool

    release, answered = threading.Event(), threading.Event()

    def slow(request: Any, response: Any) -> Any:
        release.wait(DEADLINE)  # held until the test has seen the client give up
        response.success = True
        answered.set()
        return response

    node.create_service(SetBool, topic, slow)
    wait_until(lambda: topic in peer.request("get_services"), DEADLINE, f"{topic} in get_services")
    try:
        value = peer.request("call", service=topic, args={"data": True}, call_timeout=0.5)
    except PeerError as exc:
        assert "time" in str(exc).lower(), f"the failure does not say it timed out: {exc}"
    else:
        raise AssertionError(f"the slow call succeeded: {value!r}")
    finally:
        release.set()
        answered.wait(DEADLINE)


# -- subscriptions in detail, and refused input ----------------------------------------------


def _messages(peer: PeerProcess, topic: str, handle: str, data: str) -> int:
    return sum(
        1 for e in peer.new_events()
        if e.get("event") == "message" and e.get("topic") == topic
        and e.get("handle") == handle and e["msg"].get("data") == data
    )


def two_subscriptions(
    peer: PeerProcess, node: Any, topic: str, unsubscribe_one: bool = True
) -> None:
    """Two Topic objects on one topic each get every message once; unsubscribing one keeps the other.

    roslibpy 2.1.0's ``Topic.unsubscribe`` removes every callback of the topic on
    its own side (``ros.off(name)``), so there the second half cannot be seen.
    """
    from std_msgs.msg import String

    pub = node.create_publisher(String, topic, 10)
    for handle in ("a", "b"):
        peer.request("subscribe", topic=topic, type="std_msgs/msg/String", handle=handle)
    wait_until(lambda: pub.get_subscription_count() >= 1, DEADLINE, f"bridge subscriber on {topic}")

    def both_got(data: str) -> bool:
        return _messages(peer, topic, "a", data) >= 1 and _messages(peer, topic, "b", data) >= 1

    for _ in range(int(DEADLINE / ATTEMPT)):  # until DDS has matched both ends
        pub.publish(String(data="warm-up"))
        try:
            wait_until(lambda: both_got("warm-up"), ATTEMPT, "warm-up on both")
            break
        except AssertionError:
            continue
    for data in ("x", "y", "end"):
        pub.publish(String(data=data))
    wait_until(lambda: both_got("end"), DEADLINE, "'end' on both subscriptions")
    for handle in ("a", "b"):
        counts = [_messages(peer, topic, handle, d) for d in ("x", "y")]
        assert counts == [1, 1], f"subscription {handle} got x, y {counts} times"
    if not unsubscribe_one:
        return
    peer.request("unsubscribe", topic=topic, type="std_msgs/msg/String", handle="a")
    for _ in range(int(DEADLINE / ATTEMPT)):
        pub.publish(String(data="after"))
        try:
            wait_until(lambda: _messages(peer, topic, "b", "after") >= 1, ATTEMPT, "after")
            return
        except AssertionError:
            continue
    raise AssertionError(f"the remaining subscription stopped receiving\n{peer.diagnostics()}")


def subscription_options(peer: PeerProcess, node: Any, topic: str) -> None:
    """A subscription with throttle_rate and queue_length set still delivers messages."""
    from std_msgs.msg import String

    pub = node.create_publisher(String, topic, 10)
    peer.request("subscribe", topic=topic, type="std_msgs/msg/String", throttle_rate=20,
                 queue_length=1)
    got = _ros_publish_until_delivered(peer, pub, topic, String(data="throttled"))
    assert got == {"data": "throttled"}


def subscribe_png(peer: PeerProcess, node: Any, topic: str) -> None:
    """A subscription asking for the legacy png compression still delivers messages."""
    from std_msgs.msg import String

    pub = node.create_publisher(String, topic, 10)
    peer.request("subscribe", topic=topic, type="std_msgs/msg/String", compression="png")
    got = _ros_publish_until_delivered(peer, pub, topic, String(data="png please"))
    assert got == {"data": "png please"}


def _status_about(peer: PeerProcess, about: str, topic: str) -> dict[str, Any]:
    status = peer.wait_event(
        lambda e: e.get("event") == "status" and e.get("about") == about
        and topic in (e.get("id") or ""),
        DEADLINE, f"a status about {about} on {topic}",
    )["msg"]
    assert status["level"] == "error", status
    return status  # type: ignore[no-any-return]


def bad_fields_named(peer: PeerProcess, node: Any, topic: str) -> None:
    """A publish with an unknown field or a wrong value type gets an error naming the field."""
    peer.request("publish", topic=topic, type="std_msgs/String", msg={"dta": "x"})
    assert "dta" in _status_about(peer, "publish", topic)["msg"]
    peer.begin_test()
    peer.request("publish", topic=topic, type="std_msgs/String", msg={"data": 5})
    text = _status_about(peer, "publish", topic)["msg"]
    assert "data" in text and "string" in text, text
    publish_string(peer, node, topic + "_ok", "std_msgs/String")


def subscribe_wrong_type(peer: PeerProcess, node: Any, topic: str) -> None:
    """Subscribing with a type other than the topic's gets an error naming both types."""
    from std_msgs.msg import Int32

    node.create_publisher(Int32, topic, 10)
    wait_until(lambda: peer.request("get_topic_type", topic=topic), DEADLINE, "the topic's type")
    peer.request("subscribe", topic=topic, type="std_msgs/msg/String")
    text = _status_about(peer, "subscribe", topic)["msg"]
    assert "Int32" in text and "String" in text, text


def call_bad_args(peer: PeerProcess, node: Any, topic: str) -> None:
    """A call with a wrong value type or an unknown field fails with the field's name (rosapi too)."""
    from std_srvs.srv import SetBool

    node.create_service(SetBool, topic, lambda _req, resp: resp)
    wait_until(lambda: topic in peer.request("get_services"), DEADLINE, f"{topic} in get_services")
    cases = (
        (topic, {"data": "yes"}, "data"),
        (topic, {"dta": True}, "dta"),
        ("/rosapi/topic_type", {"topik": topic}, "topik"),  # the bridge's own services too
    )
    for service, args, field in cases:
        try:
            value = peer.request("call", service=service, args=args)
        except PeerError as exc:
            assert field in str(exc), f"the error does not name {field!r}: {exc}"
        else:
            raise AssertionError(f"a call with {args} succeeded: {value!r}")


# -- more rosapi, and values JSON cannot carry as such ---------------------------------------


def get_action_servers(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer's action server list names an rclpy action server."""
    from test_msgs.action import Fibonacci

    server = _module("rclpy.action").ActionServer(
        node, Fibonacci, topic, lambda gh: None, callback_group=_own_group()
    )
    try:
        wait_until(lambda: topic in peer.request("get_action_servers"), DEADLINE,
                   f"{topic} in get_action_servers")
    finally:
        server.destroy()


def get_publishers(peer: PeerProcess, node: Any, topic: str) -> None:
    """Topic.getPublishers() names the rclpy node that publishes the topic."""
    from std_msgs.msg import String

    node.create_publisher(String, topic, 10)
    fqn = node.get_fully_qualified_name()
    wait_until(lambda: fqn in peer.request("get_publishers", topic=topic, type="std_msgs/String"),
               DEADLINE, f"{fqn} among the publishers of {topic}")


def get_time(peer: PeerProcess) -> None:
    """Ros.get_time() returns the bridge's clock as a roslibpy Time (secs/nsecs)."""
    value = peer.request("get_time")
    assert isinstance(value["secs"], int) and 0 <= value["nsecs"] < 1_000_000_000
    assert abs(value["secs"] - time.time()) < 600, f"not the system clock: {value}"


def serve_async(peer: PeerProcess, node: Any, topic: str) -> None:
    """A service served with roslib's advertiseAsync answers an rclpy caller."""
    from mult_msgs.srv import MultFloats

    peer.request("advertise_service", service=topic, type="mult_msgs/srv/MultFloats",
                 handler="mult", **{"async": True})
    response = _call_from_ros(node, MultFloats, topic, MultFloats.Request(x=-2.0, y=0.25))
    assert response.result == -0.5


def non_finite_floats(peer: PeerProcess, node: Any, topic: str) -> None:
    """NaN and infinities reach the client as null, and the finite values around them intact."""
    from std_msgs.msg import Float64MultiArray

    pub = node.create_publisher(Float64MultiArray, topic, 10)
    peer.request("subscribe", topic=topic, type="std_msgs/msg/Float64MultiArray")
    msg = Float64MultiArray(data=[1.5, math.nan, math.inf, -math.inf, -0.25])
    got = _ros_publish_until_delivered(peer, pub, topic, msg)
    assert got["data"] == [1.5, None, None, None, -0.25]


def big_integers(peer: PeerProcess, node: Any, topic: str) -> None:
    """int64 and uint64 extremes reach a Python client exactly (JSON numbers, no rounding)."""
    from test_msgs.msg import BasicTypes

    pub = node.create_publisher(BasicTypes, topic, 10)
    peer.request("subscribe", topic=topic, type="test_msgs/msg/BasicTypes")
    msg = BasicTypes(int64_value=-(2**63), uint64_value=2**64 - 1, int32_value=2**31 - 1)
    got = _ros_publish_until_delivered(peer, pub, topic, msg)
    assert (got["int64_value"], got["uint64_value"], got["int32_value"]) == (
        -(2**63), 2**64 - 1, 2**31 - 1,
    )


# -- QoS the bridge must adapt to, and concurrent calls ---------------------------------------


def _sensor_qos() -> Any:
    return _module("rclpy.qos").qos_profile_sensor_data


def subscribe_best_effort(peer: PeerProcess, node: Any, topic: str, publisher_first: bool) -> None:
    """A best-effort (sensor data QoS) rclpy publisher is heard, whether it came before or after."""
    from sensor_msgs.msg import Temperature

    pub = None
    if publisher_first:
        pub = node.create_publisher(Temperature, topic, _sensor_qos())
        wait_until(lambda: topic in _topics(peer.request("get_topics"))[0], DEADLINE,
                   f"{topic} known to the bridge")
    peer.request("subscribe", topic=topic, type="sensor_msgs/msg/Temperature")
    if pub is None:
        wait_until(lambda: node.count_subscribers(topic) >= 1, DEADLINE, "the bridge subscription")
        pub = node.create_publisher(Temperature, topic, _sensor_qos())
    got = _ros_publish_until_delivered(peer, pub, topic, Temperature(temperature=21.5, variance=0.5))
    assert (got["temperature"], got["variance"]) == (21.5, 0.5)


def concurrent_calls(peer: PeerProcess, node: Any, topic: str) -> None:
    """While one call waits on a slow rclpy service, another call on the same connection completes."""
    from std_srvs.srv import SetBool

    release = threading.Event()

    def slow(request: Any, response: Any) -> Any:
        release.wait(DEADLINE)
        response.success, response.message = True, "slow done"
        return response

    def fast(request: Any, response: Any) -> Any:
        response.success, response.message = True, "fast done"
        return response

    group = _module("rclpy.callback_groups").ReentrantCallbackGroup()
    node.create_service(SetBool, topic + "_slow", slow, callback_group=group)
    node.create_service(SetBool, topic + "_fast", fast, callback_group=group)

    def both_listed() -> bool:
        services = peer.request("get_services")
        return topic + "_slow" in services and topic + "_fast" in services

    wait_until(both_listed, DEADLINE, "both services in get_services")
    try:
        slow_seq = peer.send("call", service=topic + "_slow", args={"data": True})
        answer = peer.request("call", service=topic + "_fast", args={"data": True})
        assert answer == {"success": True, "message": "fast done"}
        assert slow_seq not in peer.replies, "the slow call finished before it was released"
    finally:
        release.set()
    slow_reply = peer.reply(slow_seq, DEADLINE)
    assert slow_reply["ok"] and slow_reply["value"]["message"] == "slow done", slow_reply


# -- the bridge restarting under a connected stock client -------------------------------------


def reconnect_after_bridge_restart(peer: PeerProcess, bridge: Any, node: Any, topic: str) -> None:
    """After the bridge crashes and comes back on its port, roslibpy's own reconnection
    restores its subscription and its served service."""
    from std_msgs.msg import String
    from std_srvs.srv import SetBool

    service = topic + "_srv"
    pub = node.create_publisher(String, topic, 10)
    peer.request("subscribe", topic=topic, type="std_msgs/msg/String")
    peer.request("advertise_service", service=service, type="std_srvs/srv/SetBool",
                 handler="setbool")
    _ros_publish_until_delivered(peer, pub, topic, String(data="before"))
    bridge.kill()
    bridge.start()
    peer.begin_test()
    got = _ros_publish_until_delivered(peer, pub, topic, String(data="after"))
    assert got == {"data": "after"}
    response = _call_from_ros(node, SetBool, service, SetBool.Request(data=True))
    assert response.message == "roslibpy got data=True"


def subscribe_without_type(peer: PeerProcess, node: Any, topic: str) -> None:
    """A subscription that names no type (roslib: none sent; roslibpy: null) takes the graph's."""
    from std_msgs.msg import String

    pub = node.create_publisher(String, topic, 10)
    wait_until(lambda: peer.request("get_topic_type", topic=topic), DEADLINE, "the topic's type")
    peer.request("subscribe", topic=topic, type=None)
    got = _ros_publish_until_delivered(peer, pub, topic, String(data="typeless"))
    assert got == {"data": "typeless"}


def client_to_client_action(server: PeerProcess, caller: PeerProcess, node: Any, topic: str) -> None:
    """A Fibonacci action roslib serves answers a goal another stock client sends."""
    server.request(
        "advertise_action", action=topic, type="test_msgs/action/Fibonacci", handler="fibonacci"
    )

    def listed() -> bool:
        refused = [e for e in server.new_events() if e.get("event") == "status"]
        assert not refused, f"the bridge refused advertise_action: {refused}"
        return topic in caller.request("get_action_servers")

    wait_until(listed, DEADLINE, f"{topic} in get_action_servers")
    value = caller.request(
        "send_goal", action=topic, type="test_msgs/action/Fibonacci", goal={"order": 5},
        goal_timeout=5.0, timeout=DEADLINE,
    )
    assert value["status"] == 4
    assert value["values"]["sequence"] == [0, 1, 1, 2, 3, 5]


def latched_to_second_client(first: PeerProcess, second: PeerProcess, node: Any, topic: str) -> None:
    """A latched message reaches a second client that subscribes after the first already has it."""
    from std_msgs.msg import String

    pub = node.create_publisher(String, topic, _latched_qos())
    pub.publish(String(data="the map"))
    for peer in (first, second):  # the second subscribes when the bridge already listens
        peer.request("subscribe", topic=topic, type="std_msgs/msg/String")
        got = peer.wait_event(
            lambda e: e.get("event") == "message" and e.get("topic") == topic, DEADLINE,
            f"the latched message on {topic}",
        )
        assert got["msg"] == {"data": "the map"}


def mixed_encodings(json_peer: PeerProcess, cbor_peer: PeerProcess, node: Any, topic: str) -> None:
    """One topic, one client on JSON and one on CBOR: each gets the message in its own form."""
    from std_msgs.msg import Float64MultiArray

    pub = node.create_publisher(Float64MultiArray, topic, 10)
    json_peer.request("subscribe", topic=topic, type="std_msgs/msg/Float64MultiArray")
    cbor_peer.request("subscribe", topic=topic, type="std_msgs/msg/Float64MultiArray",
                      compression="cbor")
    msg = Float64MultiArray(data=[0.5, 2.0])
    got_json = _ros_publish_until_delivered(json_peer, pub, topic, msg)
    got_cbor = _ros_publish_until_delivered(cbor_peer, pub, topic, msg)
    assert got_json["data"] == [0.5, 2.0]
    assert got_cbor["data"] == {"$typed": "Float64Array", "values": [0.5, 2.0]}


def hears_itself(peer: PeerProcess, node: Any, topic: str) -> None:
    """A client subscribed to a topic it also publishes gets its own messages back (as ROS does)."""
    peer.request("subscribe", topic=topic, type="std_msgs/msg/String")
    peer.request("advertise", topic=topic, type="std_msgs/msg/String")
    wait_until(lambda: node.count_publishers(topic) >= 1 and node.count_subscribers(topic) >= 1,
               DEADLINE, f"the bridge's publisher and subscriber on {topic}")
    for _ in range(int(DEADLINE / ATTEMPT)):
        _refusal(peer, topic)
        peer.request("publish", topic=topic, type="std_msgs/msg/String", msg={"data": "echo"})
        try:
            got = peer.wait_event(
                lambda e: e.get("event") == "message" and e.get("topic") == topic, ATTEMPT
            )
        except AssertionError:
            continue
        assert got["msg"] == {"data": "echo"}
        return
    raise AssertionError(f"{peer.name} never heard its own message\n{peer.diagnostics()}")


def relative_names(peer: PeerProcess, node: Any, topic: str) -> None:
    """Topic names without the leading slash ("chatter") mean the absolute ones ("/chatter")."""
    from std_msgs.msg import String

    relative = topic.lstrip("/")
    inbox: queue.Queue[Any] = queue.Queue()
    node.create_subscription(String, topic + "_in", inbox.put, 10)
    pub = node.create_publisher(String, topic + "_out", 10)
    peer.request("subscribe", topic=relative + "_out", type="std_msgs/msg/String")
    peer.request("advertise", topic=relative + "_in", type="std_msgs/msg/String")
    wait_until(lambda: node.count_publishers(topic + "_in") >= 1, DEADLINE, "the bridge publisher")
    got = _publish_until_received(peer, relative + "_in", "std_msgs/msg/String", {"data": "in"}, inbox)
    assert got.data == "in"
    # The bridge's subscription is matched with our publisher, so a message gets through
    # within a few attempts, or its delivery to the app is broken.
    wait_until(lambda: pub.get_subscription_count() >= 1, DEADLINE, "the bridge subscription")
    for _ in range(6):
        pub.publish(String(data="out"))
        try:
            event = peer.wait_event(
                lambda e: e.get("event") == "message"
                and e.get("topic") in (relative + "_out", topic + "_out"),
                ATTEMPT,
            )
        except AssertionError:
            continue
        assert event["msg"] == {"data": "out"}
        return
    raise AssertionError(f"{peer.name} got nothing on {relative}_out\n{peer.diagnostics()}")


def serve_relative_name(peer: PeerProcess, node: Any, topic: str) -> None:
    """A service the client advertises without the leading slash answers ROS callers."""
    from std_srvs.srv import SetBool

    peer.request("advertise_service", service=topic.lstrip("/"), type="std_srvs/srv/SetBool",
                 handler="setbool")
    client = node.create_client(SetBool, topic)
    try:
        assert client.wait_for_service(timeout_sec=DEADLINE), f"{topic} never appeared"
        done = threading.Event()
        future = client.call_async(SetBool.Request(data=True))
        future.add_done_callback(lambda _f: done.set())
        # The server is matched already, so the request reaches the client's handler at
        # once, or never (the bridge would answer the caller by itself after its timeout).
        peer.wait_event(lambda e: e.get("event") == "request", 5.0,
                        "the request in the client's service handler")
        assert done.wait(DEADLINE), f"no response from {topic}"
        response = future.result()
    finally:
        node.destroy_client(client)
    assert response.success is True
    assert response.message.endswith("got data=True")



def client_to_client_failure(server: PeerProcess, caller: PeerProcess, node: Any, topic: str) -> None:
    """When one client's service handler reports failure, another client's call fails too."""
    server.request("advertise_service", service=topic, type="std_srvs/srv/SetBool", handler="fail")

    def listed() -> bool:
        return topic in {name for name, _types in node.get_service_names_and_types()}

    wait_until(listed, DEADLINE, f"{topic} in the ROS graph")
    try:
        value = _call_new_service(caller, topic, {"data": True})
    except PeerError as exc:
        assert "Timeout" not in str(exc), f"the caller timed out instead of being told: {exc}"
    else:
        raise AssertionError(f"the call succeeded although the handler failed: {value!r}")


def cancel_goal(peer: PeerProcess, node: Any, topic: str) -> None:
    """A goal the client cancels after its first feedback ends canceled, through the client's error path."""
    from test_msgs.action import Fibonacci

    action = _module("rclpy.action")
    canceled, finished = threading.Event(), threading.Event()

    def execute(goal_handle: Any) -> Any:
        sequence = [0, 1]
        deadline = time.monotonic() + DEADLINE
        while time.monotonic() < deadline and not finished.is_set():  # a long, cancellable job
            if goal_handle.is_cancel_requested:
                goal_handle.canceled()
                canceled.set()
                return Fibonacci.Result(sequence=sequence)
            goal_handle.publish_feedback(Fibonacci.Feedback(sequence=sequence))
            time.sleep(0.05)
        goal_handle.abort()
        return Fibonacci.Result(sequence=sequence)

    server = action.ActionServer(
        node, Fibonacci, topic, execute,
        cancel_callback=lambda _request: action.CancelResponse.ACCEPT,
        callback_group=_module("rclpy.callback_groups").ReentrantCallbackGroup(),
    )
    try:
        # As upstream rosbridge does: a goal that ran to CANCELED ends with result true, its
        # status and values, so a stock client's result callback hears of it (roslibpy's own
        # upstream test_cancel waits for exactly that).
        # roslib (npm) reports a canceled goal as an error that names it, with its values.
        try:
            value = peer.request(
                "send_goal", action=topic, type="test_msgs/action/Fibonacci", goal={"order": 50},
                cancel_after_feedback=True, timeout=DEADLINE,
            )
        except PeerError as exc:
            assert "canceled" in str(exc).lower() and '"sequence":[0,1]' in str(exc), exc
        else:
            assert value["status"] == 5, value  # CANCELED
            assert value["values"]["sequence"] == [0, 1], value
        assert canceled.is_set(), "the rclpy action server never saw the cancel request"
    finally:
        finished.set()
        server.destroy()
