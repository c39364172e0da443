"""Recording and playing MCAP through the real bridge, checked with an independent reader and
writer (mcap-ros2-support) and real rclpy publishers and subscribers."""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from mcap_ros2.writer import Writer as Ros2Writer
from nav_msgs.msg import OccupancyGrid
from rclpy.qos import DurabilityPolicy, QoSProfile
from robot_msgs.msg import Status as RosStatus
from sensor_msgs.msg import Image as RosImage
from sensor_msgs.msg import Imu as RosImu

import roslibpy_lite
from msgs.dynamic import full_text
from msgs.sensor_msgs.msg import Imu
from roslibpy_lite import Client, MockRos
from roslibpy_lite.bag import Recorder, info, play, read
from tests.helpers import BridgeProcess, ros_image

W, H = 64, 48



def _theirs(path: Path, topics: list[str] | None = None) -> list[Any]:
    """(schema, channel, message, decoded) from the independent reader (mcap_ros2)."""
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return list(reader.iter_decoded_messages(topics=topics, log_time_order=True))


def _image(i: int) -> RosImage:
    return ros_image(W, H, "rgb8", bytes((i + k) % 251 for k in range(W * H * 3)), f"cam{i}")


def _imu(i: int) -> RosImu:
    msg = RosImu()
    msg.header.frame_id = "imu"
    msg.header.stamp.sec = i
    msg.linear_acceleration.z = 9.81 + i
    return msg


def _status(i: int) -> RosStatus:
    msg = RosStatus(mode=1, label=f"s{i}", battery_cells=[3.5, float(i)])
    msg.header.frame_id = "base"
    return msg


async def _until(condition: Any, action: Any, what: str, timeout: float = 30) -> None:
    """Run ``action`` every 20 ms until ``condition()`` (publishing until the graph has
    matched: discovery has no event to await)."""
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        action()
        await asyncio.sleep(0.02)


async def test_a_recording_through_the_bridge_reads_back_as_rclpy_published(
    client: Client, ros_node: Any, topic: str, tmp_path: Path
) -> None:
    """Image, IMU, the robot's own type and a latched map, recorded with cbor-raw; the
    independent reader (mcap_ros2) and ours give back what rclpy published."""
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)  # type: ignore[no-untyped-call]
    grid = OccupancyGrid()
    grid.header.frame_id = "map"
    grid.info.width, grid.info.height = 4, 2
    grid.data = [0, 100, -1, 50, 0, 0, 100, 100]
    map_pub = ros_node.create_publisher(OccupancyGrid, f"{topic}/map", latched)
    map_pub.publish(grid)
    pubs = {f"{topic}/image": (ros_node.create_publisher(RosImage, f"{topic}/image", 10), _image),
            f"{topic}/imu": (ros_node.create_publisher(RosImu, f"{topic}/imu", 10), _imu),
            f"{topic}/status": (ros_node.create_publisher(RosStatus, f"{topic}/status", 10),
                                _status)}
    sent: dict[str, list[Any]] = {name: [] for name in pubs}
    path = tmp_path / "run.mcap"
    async with Recorder(client, path, topics=[f"{topic}/*"], discover_every=0.2) as rec:
        def publish() -> None:
            for name, (pub, make) in pubs.items():
                msg = make(len(sent[name]))
                sent[name].append(msg)
                pub.publish(msg)

        def enough() -> bool:
            counts = rec.stats.per_topic
            return (all(counts.get(name, 0) >= 5 for name in pubs)
                    and counts.get(f"{topic}/map", 0) >= 1)

        await _until(enough, publish, "5 messages on each topic and the map")
    stats = rec.stats
    assert stats.error is None and stats.dropped == 0 and stats.files == [path]
    theirs: dict[str, list[Any]] = {}
    for schema, channel, message, decoded in _theirs(path):
        assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
        theirs.setdefault(channel.topic, []).append((message, decoded))
    assert {name: len(v) for name, v in theirs.items()} == stats.per_topic
    for name in pubs:
        got = theirs[name]
        # what was recorded is a run of what was published, in order (the first ones may
        # have gone out before the bridge's subscription matched)
        first = next(i for i, s in enumerate(sent[name]) if _same(s, got[0][1]))
        for offset, (_, decoded) in enumerate(got):
            assert _same(sent[name][first + offset], decoded), name
        times = [message.log_time for message, _ in got]
        assert times == sorted(times)
        assert all(message.publish_time <= message.log_time for message, _ in got)
    assert list(theirs[f"{topic}/map"][0][1].data) == list(grid.data)
    ours = [m.decode().label for m in read(path, [f"{topic}/status"])]  # type: ignore[attr-defined]
    assert ours == [decoded.label for _, decoded in theirs[f"{topic}/status"]]
    about = info(path)
    assert about.complete and about.messages == stats.messages
    assert {t.topic: t.type_name for t in about.topics}[f"{topic}/status"] == \
        "robot_msgs/msg/Status"


def _same(ros: Any, theirs: Any) -> bool:
    """A message rclpy published equals one the independent reader decoded."""
    if isinstance(ros, RosImage):
        return (ros.header.frame_id, bytes(ros.data)) == (theirs.header.frame_id,
                                                         bytes(theirs.data))
    if isinstance(ros, RosImu):
        return (ros.header.stamp.sec, ros.linear_acceleration.z) == (
            theirs.header.stamp.sec, theirs.linear_acceleration.z)
    return (ros.label, list(ros.battery_cells)) == (theirs.label, list(theirs.battery_cells))


async def test_a_file_from_the_independent_writer_plays_into_rclpy_in_order(
    client: Client, ros_node: Any, topic: str, tmp_path: Path
) -> None:
    """mcap_ros2 writes 20 IMU messages 20 ms apart; play publishes them through the bridge
    to an rclpy subscriber, in order, each equal to what was written."""
    path = tmp_path / "theirs.mcap"
    with path.open("wb") as f:
        writer = Ros2Writer(f)
        schema = writer.register_msgdef("sensor_msgs/msg/Imu", full_text("sensor_msgs/msg/Imu"))
        t0 = 1_700_000_000_000_000_000
        for i in range(20):
            writer.write_message(topic, schema, {"header": {"stamp": {"sec": i, "nanosec": 0},
                                                            "frame_id": "imu"},
                                                 "linear_acceleration": {"x": 0.0, "y": 0.0,
                                                                         "z": 9.81 + i}},
                                 log_time=t0 + i * 20_000_000, publish_time=t0 + i * 20_000_000)
        writer.finish()  # type: ignore[no-untyped-call]
    about = info(path)
    assert about.messages == 20 and abs(about.duration - 0.38) < 1e-6
    got: list[tuple[float, Any]] = []
    warmed: list[Any] = []

    def on_imu(m: Any) -> None:
        (warmed if m.header.frame_id == "warm" else got).append((time.monotonic(), m))

    ros_node.create_subscription(RosImu, topic, on_imu, 50)
    warm = await client.advertise(topic, Imu)  # play shares this advertise, already matched
    ping = Imu.from_json({"header": {"frame_id": "warm"}})
    await _until(lambda: bool(warmed), lambda: asyncio.ensure_future(warm.publish(ping)),
                 "the bridge's publisher to match")
    began = time.monotonic()
    stats = await play(client, path)
    took = time.monotonic() - began
    await _until(lambda: len(got) >= 20, lambda: None, "20 played messages", timeout=15)
    assert [m.header.stamp.sec for _, m in got] == list(range(20))
    assert [m.linear_acceleration.z for _, m in got] == [9.81 + i for i in range(20)]
    assert stats.messages == 20 and stats.topics == 1
    assert took >= 0.38 - 1e-3, took  # the last message waits for its recorded time
    spread = got[-1][0] - got[0][0]  # recorded: 0.38 s; printed for the record, not asserted
    print(f"played 0.38 s of messages in {spread:.3f} s; late by {stats.late_mean_ms:.2f} ms "
          f"on average, {stats.late_max_ms:.2f} ms at most")


async def test_mockros_records_what_the_code_under_test_publishes(tmp_path: Path) -> None:
    """On MockRos (no rosapi: topics named with their types) the file reads back typed, the
    robot's own type included; the independent reader agrees."""
    from tests.msgs.test_dynamic import _definition

    roslibpy_lite.define_type("robot_msgs/msg/Status", _definition("robot_msgs/msg/Status"))
    path = tmp_path / "unit.mcap"
    async with MockRos() as ros:
        topics = {"/chatter": "std_msgs/msg/String", "/status": "robot_msgs/msg/Status"}
        async with Recorder(ros, path, topics=topics, max_messages=6) as rec:
            chatter = await ros.advertise("/chatter", "std_msgs/msg/String")
            status = await ros.advertise("/status", "robot_msgs/msg/Status")
            with pytest.warns(roslibpy_lite.PartialMessageWarning, match="Status dict lacks"):
                for i in range(3):
                    await chatter.publish({"data": f"hello {i}"})
                    await status.publish({"label": f"s{i}", "mode": 1})
            await rec.wait(5)
    assert rec.stats.messages == 6
    ours = [(m.topic, m.decode()) for m in read(path)]
    assert [msg.data for t, msg in ours  # type: ignore[attr-defined]
            if t == "/chatter"] == ["hello 0", "hello 1", "hello 2"]
    assert [msg.label for t, msg in ours  # type: ignore[attr-defined]
            if t == "/status"] == ["s0", "s1", "s2"]
    theirs = [decoded.label for _, _, _, decoded in _theirs(path, ["/status"])]
    assert theirs == ["s0", "s1", "s2"]


async def test_a_full_disk_ends_the_recording_with_a_clear_error() -> None:
    """Writing to /dev/full: the recording stops, saying why; nothing raises in callbacks."""
    async with MockRos() as ros:
        rec = Recorder(ros, "/dev/full", topics={"/chatter": "std_msgs/msg/String"},
                       chunk_size=1024)
        await rec.start()
        pub = await ros.advertise("/chatter", "std_msgs/msg/String")
        for i in range(2000):
            if rec.stats.error is not None:
                break
            await pub.publish({"data": "x" * 100 + str(i)})
        stats = await rec.stop()
    assert stats.error is not None and "No space left on device" in stats.error, stats


def _cli(*argv: str) -> list[str]:
    return [sys.executable, "-m", "roslibpy_lite.cli", *argv]


_SIGNALS = {"sigint": signal.SIGINT, "sigint-in-background": signal.SIGINT,
            "sigterm": signal.SIGTERM, "sigkill": signal.SIGKILL}


def _as_background_job() -> None:
    # what `cmd &` in a script does: the child starts with SIGINT ignored
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@pytest.mark.parametrize("how", list(_SIGNALS))
async def test_the_cli_recorder_ends_properly_on_ctrl_c_and_a_killed_one_stays_readable(
    bridge: BridgeProcess, ros_node: Any, topic: str, tmp_path: Path, how: str
) -> None:
    """``bag record`` in its own process: Ctrl+C finishes the file (summary and all), and so
    do SIGTERM and a SIGINT to a recorder started as a background job (SIGINT inherited
    ignored); a kill -9 leaves it readable up to its last chunk. ``bag info`` describes all."""
    path = tmp_path / "cli.mcap"
    pub = ros_node.create_publisher(RosImage, topic, 10)
    proc = subprocess.Popen(_cli("bag", "record", topic, "-o", str(path), "--url", bridge.url),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"},
                            preexec_fn=_as_background_job if how.endswith("background") else None)
    images: dict[str, bytes] = {}
    try:
        def publish() -> None:
            msg = _image(0)
            msg.header.frame_id = f"cam{len(images)}"
            msg.data = images[msg.header.frame_id] = os.urandom(W * H * 3)  # no compression
            pub.publish(msg)

        # 256 KiB chunks: a few dozen 9 KiB images make the first one reach the disk
        await _until(lambda: path.exists() and path.stat().st_size > 300_000, publish,
                     "the recording's first chunks")
        proc.send_signal(_SIGNALS[how])
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    about = info(path)
    assert about.messages > 0 and about.topics[0].topic == topic
    assert about.complete == (how != "sigkill"), (out, err)
    if how != "sigkill":
        assert proc.returncode == 0 and "recorded" in out, (out, err)
        assert about.messages == len(list(read(path)))
    frames = [m.decode() for m in read(path)]
    assert all(f.data == images[f.header.frame_id] for f in frames)  # type: ignore[attr-defined]
    shown = subprocess.run(_cli("bag", "info", str(path)), capture_output=True, text=True,
                           timeout=60)
    assert shown.returncode == 0 and topic in shown.stdout and "sensor_msgs/msg/Image" in \
        shown.stdout, shown
