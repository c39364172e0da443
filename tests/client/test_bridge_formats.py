"""Wire formats against the real bridge: JSON base64 and CBOR (byte strings, typed arrays)."""

from __future__ import annotations

import asyncio
import warnings
from collections.abc import Callable
from typing import Any

import pytest

import roslibpy_lite
from msgs.sensor_msgs.msg import Image
from msgs.std_msgs.msg import Float32MultiArray
from roslibpy_lite import Client, RosTimeoutError, Subscription

with warnings.catch_warnings():
    warnings.filterwarnings("ignore", "module 'sre_.*' is deprecated", DeprecationWarning)
    import rosidl_generator_py  # noqa: F401

from sensor_msgs.msg import Image as RosImage
from std_msgs.msg import Float32MultiArray as RosFloats

from tests.helpers import ros_image

W, H = 64, 48
PIXELS = bytes(i % 251 for i in range(W * H * 3))



async def first_message(publish: Callable[[], None], sub: Subscription[Any], timeout: float = 15) -> Any:
    """Publish from rclpy until the subscription hears something (discovery has no event)."""
    deadline = asyncio.get_running_loop().time() + timeout
    while True:
        publish()
        try:
            return await sub.get(0.25)
        except RosTimeoutError:
            if asyncio.get_running_loop().time() > deadline:
                raise


@pytest.mark.parametrize("compression", ["none", "cbor", "cbor-raw"])
async def test_image_arrives_typed(client: Client, ros_node: Any, topic: str, compression: str) -> None:
    """An rclpy rgb8 image reaches a typed subscription with its bytes intact (JSON, CBOR, and
    cbor-raw: the CDR bytes from ROS, decoded here)."""
    pub = ros_node.create_publisher(RosImage, topic, 10)
    async with client.subscribe(topic, Image, compression=compression) as sub:
        msg = await first_message(lambda: pub.publish(ros_image(W, H, "rgb8", PIXELS, "cam")), sub)
    assert isinstance(msg, Image)
    assert (msg.width, msg.height, msg.encoding, msg.header.frame_id) == (W, H, "rgb8", "cam")
    assert msg.data == PIXELS


async def test_image_as_dict_json_is_base64_cbor_is_bytes(
    client: Client, ros_node: Any, topic: str
) -> None:
    """Dict subscriptions get uint8[] as bytes over JSON (the bridge's base64 text decoded
    here) as over CBOR."""
    pub = ros_node.create_publisher(RosImage, topic, 10)
    async with client.subscribe(topic, "sensor_msgs/msg/Image") as as_json:
        msg = await first_message(lambda: pub.publish(ros_image(W, H, "rgb8", PIXELS, "cam")), as_json)
    assert type(msg["data"]) is bytes and msg["data"] == PIXELS
    # Another topic: frames of the JSON subscription may still be in flight on this one.
    pub2 = ros_node.create_publisher(RosImage, topic + "_cbor", 10)
    async with client.subscribe(topic + "_cbor", "sensor_msgs/msg/Image",
                                compression="cbor") as as_cbor:
        msg = await first_message(lambda: pub2.publish(ros_image(W, H, "rgb8", PIXELS, "cam")), as_cbor)
    assert msg["data"] == PIXELS


async def test_float_array_over_cbor_typed_arrays(client: Client, ros_node: Any, topic: str) -> None:
    """A float32 array sent as an RFC 8746 typed array decodes to the same numbers."""
    pub = ros_node.create_publisher(RosFloats, topic, 10)
    values = [0.5, -1.25, 3.0, 1e-3]
    async with client.subscribe(topic, Float32MultiArray, compression="cbor") as sub:
        msg = await first_message(lambda: pub.publish(RosFloats(data=values)), sub)
    assert msg.data == pytest.approx(values)


async def test_fragmented_messages_are_reassembled(client: Client, ros_node: Any, topic: str) -> None:
    """With fragment_size the bridge splits each image into fragments; the client reassembles them."""
    pub = ros_node.create_publisher(RosImage, topic, 10)
    async with client.subscribe(topic, Image, fragment_size=1000) as sub:
        msg = await first_message(lambda: pub.publish(ros_image(W, H, "rgb8", PIXELS, "cam")), sub)
    assert msg.data == PIXELS
    assert client._ws._protocol.pending_fragments == 0


async def test_cbor_raw_gives_what_cbor_gives(client: Client, ros_node: Any, topic: str) -> None:
    """The same Imu and Image as dicts over cbor and over cbor-raw: equal, field for field."""
    from sensor_msgs.msg import Imu as RosImu

    imu = RosImu()
    imu.header.frame_id = "imu"
    imu.orientation.w = 0.5
    imu.angular_velocity.z = -1.25
    imu.linear_acceleration_covariance = [float(i) for i in range(9)]
    for ros_cls, msg, type_name in ((RosImu, imu, "sensor_msgs/msg/Imu"),
                                    (RosImage, ros_image(W, H, "rgb8", PIXELS, "cam"), "sensor_msgs/msg/Image")):
        name = f"{topic}_{ros_cls.__name__}"
        pub = ros_node.create_publisher(ros_cls, name, 10)
        got = []
        for compression in ("cbor", "cbor-raw"):
            async with client.subscribe(name, type_name, compression=compression) as sub:
                got.append(await first_message(lambda: pub.publish(msg), sub))  # noqa: B023 - awaited here
        assert got[0] == got[1], type_name
    assert got[1]["data"] == PIXELS


async def test_cbor_raw_needs_the_type_here(client: Client, topic: str) -> None:
    """cbor-raw for a type msgs does not know is refused at the call, saying why."""
    with pytest.raises(roslibpy_lite.UsageError, match=r"cbor-raw.*definition"):
        client.subscribe(topic, "robot_only_msgs/msg/Secret", compression="cbor-raw")
