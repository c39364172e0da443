"""The relay's CBOR is the bridge's CBOR (issue 26): numeric arrays as RFC 8746 typed arrays.

A robot's bridge that also listens serves one rclpy message straight and, through its
exporter, to a relay; a ``compression: cbor`` subscriber on each gets the same CBOR object,
the relay's made from the CDR bytes without ROS (``msgs.cdr``'s typed decoder).
"""

from __future__ import annotations

import struct
from typing import Any

import cbor2
import pytest

from tests.helpers import open_wire
from tests.relay.support import ROBOT, free_port, robot_reachable, start_relay, start_robot

pytestmark = pytest.mark.timeout(90)

VALUES: dict[str, list[Any]] = {
    "float64_values": [1.5, -2.25, 1e300],
    "float32_values": [0.5, -8.0, 3.25],
    "uint8_values": [0, 7, 255],
    "char_values": [65, 66, 67],
    "byte_values": [b"\x00", b"\x10", b"\xff"],
    "int8_values": [-128, 0, 127],
    "int16_values": [-300, 1, 300],
    "uint16_values": [0, 1, 65535],
    "int32_values": [-5, 0, 2**31 - 1],
    "uint32_values": [0, 1, 2**32 - 1],
    "int64_values": [-(2**63), 0, 2**63 - 1],
    "uint64_values": [0, 1, 2**64 - 1],
    "bool_values": [True, False, True],
    "string_values": ["a", "", "ü"],
}


@pytest.mark.parametrize("type_name", ["test_msgs/msg/UnboundedSequences", "test_msgs/msg/Arrays"])
async def test_relay_cbor_equals_the_bridges(ros_node: Any, topic: str, type_name: str) -> None:
    """float64[]/uint8[]/int32[] and every other array field, sequences and fixed arrays:
    what a relay's CBOR subscriber decodes equals what the bridge sends for the same
    message, numeric arrays as typed arrays."""
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from test_msgs import msg as test_msgs

    cls = getattr(test_msgs, type_name.rsplit("/", 1)[1])
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)  # type: ignore[no-untyped-call]
    pub = ros_node.create_publisher(cls, topic, latched)
    pub.publish(cls(**VALUES, alignment_check=7))
    router = f"tcp/127.0.0.1:{free_port()}"
    relay = await start_relay(listen=router)
    robot, exporter = await start_robot(router, websocket=True)
    try:
        await robot_reachable(relay)
        got = []
        for url in (f"ws://127.0.0.1:{robot.port}", f"ws://127.0.0.1:{relay.port}/{ROBOT}"):
            ws = await open_wire(url)
            try:
                await ws.send({"op": "subscribe", "topic": topic, "type": type_name,
                               "compression": "cbor"})
                got.append((await ws.expect(op="publish", topic=topic, timeout=20))["msg"])
            finally:
                await ws.close()
        straight, relayed = got
        assert straight["float64_values"] == cbor2.CBORTag(
            86, struct.pack("<3d", *VALUES["float64_values"]))  # little-endian float64
        assert straight["int32_values"] == cbor2.CBORTag(
            78, struct.pack("<3i", *VALUES["int32_values"]))  # little-endian int32
        assert straight["uint8_values"] == bytes(VALUES["uint8_values"])
        assert relayed == straight
    finally:
        await relay.close()
        await exporter.close()
        await robot.close()

