"""roslibpy_lite.data on real data: what rclpy publishes through the bridge, in every
compression, as arrays; an MCAP file written by another tool, as a table."""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

import roslibpy_lite
from msgs.dynamic import full_text
from msgs.sensor_msgs.msg import Image, PointCloud2
from roslibpy_lite import Client
from roslibpy_lite.data import bag_to_dataframe, to_numpy
from tests.client.test_bridge_formats import first_message

with warnings.catch_warnings():
    warnings.filterwarnings("ignore", "module 'sre_.*' is deprecated", DeprecationWarning)
    import rosidl_generator_py  # noqa: F401

from sensor_msgs.msg import Image as RosImage
from sensor_msgs.msg import PointCloud2 as RosCloud
from sensor_msgs.msg import PointField as RosField

from tests.helpers import ros_image

H, W = 24, 32
PIXELS = np.random.default_rng(3).integers(0, 255, size=(H, W, 3), dtype=np.uint8)
POINTS = np.zeros(H * W, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("ring", "<u2")])
POINTS["x"] = np.arange(H * W) * 0.5
POINTS["z"] = -1.25
POINTS["ring"] = np.arange(H * W) % 16


def _cloud() -> Any:
    msg = RosCloud(height=H, width=W, point_step=POINTS.itemsize,
                   row_step=W * POINTS.itemsize, is_dense=True)
    msg.fields = [RosField(name="x", offset=0, datatype=7, count=1),
                  RosField(name="y", offset=4, datatype=7, count=1),
                  RosField(name="z", offset=8, datatype=7, count=1),
                  RosField(name="ring", offset=12, datatype=4, count=1)]
    msg.data = POINTS.tobytes()
    return msg


@pytest.mark.parametrize(("compression", "typed"), [
    ("none", False), ("none", True), ("cbor", False), ("cbor", True), ("cbor-raw", True)])
async def test_images_and_clouds_from_rclpy_are_the_same_arrays(
    client: Client, ros_node: Any, topic: str, compression: str, typed: bool
) -> None:
    """An rclpy Image and PointCloud2 reach to_numpy as the pixels and points published,
    whatever the compression and whether the subscription is typed or gives dicts."""
    image_pub = ros_node.create_publisher(RosImage, f"{topic}/image", 10)
    cloud_pub = ros_node.create_publisher(RosCloud, f"{topic}/cloud", 10)
    image_type: Any = Image if typed else "sensor_msgs/msg/Image"
    cloud_type: Any = PointCloud2 if typed else "sensor_msgs/msg/PointCloud2"
    async with client.subscribe(f"{topic}/image", image_type, compression=compression) as sub:
        image = await first_message(lambda: image_pub.publish(ros_image(W, H, "bgr8", PIXELS.tobytes())), sub)
    async with client.subscribe(f"{topic}/cloud", cloud_type, compression=compression) as sub:
        cloud = await first_message(lambda: cloud_pub.publish(_cloud()), sub)
    pixels = to_numpy(image)
    assert pixels.shape == (H, W, 3)
    np.testing.assert_array_equal(pixels, PIXELS)
    points = to_numpy(cloud)
    assert points.shape == (H * W,)
    for name in POINTS.dtype.names or ():
        np.testing.assert_array_equal(points[name], POINTS[name])


BAYER = np.random.default_rng(5).integers(0, 65535, size=(H, W), endpoint=True,
                                          dtype=np.uint16)
BAYER[0, :4] = [0x0102, 0xFF00, 0x00FF, 0xFFFF]  # both bytes of each pixel matter


@pytest.mark.parametrize(("compression", "typed", "big"), [
    ("none", False, False), ("cbor", True, False), ("none", False, True)])
async def test_a_16_bit_bayer_image_is_uint16_pixels(
    client: Client, ros_node: Any, topic: str, compression: str, typed: bool, big: bool
) -> None:
    """An rclpy bayer_rggb16 Image reaches to_numpy as one uint16 per pixel with the values
    published (little- and big-endian), not as its bytes read as 8-bit pixels."""
    pub = ros_node.create_publisher(RosImage, topic, 10)
    frame = RosImage(height=H, width=W, encoding="bayer_rggb16", step=W * 2,
                     is_bigendian=int(big))
    frame.data = BAYER.astype(">u2" if big else "<u2").tobytes()
    image_type: Any = Image if typed else "sensor_msgs/msg/Image"
    async with client.subscribe(topic, image_type, compression=compression) as sub:
        image = await first_message(lambda: pub.publish(frame), sub)
    pixels = to_numpy(image)
    assert pixels.shape == (H, W) and pixels.dtype.kind == "u" and pixels.dtype.itemsize == 2
    np.testing.assert_array_equal(pixels, BAYER)


def test_a_topic_of_another_tools_mcap_file_as_a_table(tmp_path: Path) -> None:
    """bag_to_dataframe reads one topic of a file mcap_ros2 wrote: header stamps index the
    IMU's rows; a topic without headers is indexed by when it was recorded."""
    from mcap_ros2.writer import Writer

    path = tmp_path / "theirs.mcap"
    t0 = 1_700_000_000_000_000_000
    with path.open("wb") as f:
        writer = Writer(f)
        imu = writer.register_msgdef("sensor_msgs/msg/Imu", full_text("sensor_msgs/msg/Imu"))
        text = writer.register_msgdef("std_msgs/msg/String", "string data")
        for i in range(50):
            writer.write_message("/imu", imu, {
                "header": {"stamp": {"sec": 1000 + i // 10, "nanosec": (i % 10) * 100_000_000},
                           "frame_id": "imu"},
                "angular_velocity": {"x": 0.1 * i, "y": 0.0, "z": -0.5}},
                log_time=t0 + i * 5_000_000, publish_time=t0 + i * 5_000_000)
            if i % 10 == 0:
                writer.write_message("/note", text, {"data": f"note {i}"},
                                     log_time=t0 + i * 5_000_000, publish_time=t0)
        writer.finish()  # type: ignore[no-untyped-call]
    frame = bag_to_dataframe(path, "/imu", fields=["angular_velocity.x", "angular_velocity.z"])
    assert list(frame.columns) == ["angular_velocity.x", "angular_velocity.z"]
    assert len(frame) == 50
    assert frame["angular_velocity.x"].iloc[7] == pytest.approx(0.7)
    assert frame.index[13] == pd.Timestamp(1001_300_000_000, unit="ns", tz="UTC")
    notes = bag_to_dataframe(path, "/note")
    assert list(notes["data"]) == [f"note {i}" for i in range(0, 50, 10)]
    assert notes.index[1] == pd.Timestamp(t0 + 50_000_000, unit="ns", tz="UTC")
    with pytest.raises(roslibpy_lite.UsageError,
                       match=r"no message on /camera/info; the topics are: /imu, /note$"):
        bag_to_dataframe(path, "/camera/info")
    with pytest.raises(roslibpy_lite.UsageError, match="no message on /Imu; did you mean '/imu'"):
        bag_to_dataframe(path, "/Imu")


def test_a_table_of_frames_does_not_hold_the_frames(tmp_path: Path) -> None:
    """bag_to_dataframe keeps each message's chosen fields, not the decoded messages: a
    table of 30 camera frames' headers peaks far below the 27 MB of their pixels."""
    import tracemalloc

    from bench.dataframe import CAMERA, write_recording

    path = tmp_path / "camera.mcap"
    assert write_recording(path, seconds=1.0)[CAMERA] == 30
    tracemalloc.start()
    try:
        frame = bag_to_dataframe(path, CAMERA, ["header.frame_id", "width", "height"])
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert list(frame.columns) == ["header.frame_id", "width", "height"] and len(frame) == 30
    pixels = 30 * 640 * 480 * 3
    assert peak < pixels / 3, f"peak {peak / 2**20:.1f} MiB for {pixels / 2**20:.1f} MiB of pixels"
