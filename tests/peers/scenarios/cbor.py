"""CBOR scenarios (roslib decodes it): messages, bytes, raw CDR and typed arrays sent as CBOR, and
JSON and CBOR clients side by side.
"""

from __future__ import annotations

import importlib
from typing import Any

from tests.helpers import wait_until
from tests.peers.peer import PeerProcess
from tests.peers.scenarios.support import (
    DEADLINE,
    _ros_publish_until_delivered,
)

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


# -- JSON and CBOR clients side by side --------------------------------------------------------


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
