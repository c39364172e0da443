"""Recording across a dropped link and into split files, and the blocking client's bag API,
against the real bridge and checked with the independent reader (mcap-ros2-support)."""

from __future__ import annotations

import asyncio
import threading
import time
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader
from rclpy.qos import DurabilityPolicy, QoSProfile
from std_msgs.msg import Int32

import roslibpy_lite
from bench.linkproxy import LinkProxy
from roslibpy_lite import sync
from roslibpy_lite.api import ConnectionState
from roslibpy_lite.bag import Recorder, info, read
from roslibpy_lite.sync import bag as sync_bag
from tests.bag.test_bag import _image, _theirs, _until
from tests.helpers import BridgeProcess, async_wait_until, wait_until


async def test_a_reconnect_goes_on_in_the_same_file_and_says_how_long_the_gap_was(
    bridge: BridgeProcess, ros_node: Any, topic: str, tmp_path: Path
) -> None:
    """10 Hz Int32 across a 3 s blackhole of the link: the client reconnects and resumes its
    session, the recording goes on in the one file, every number is in it once and in
    order (what the robot published meanwhile too), and the gap is in the stats and in
    the file's roslibpy_lite metadata."""
    path = tmp_path / "gap.mcap"
    # transient local with room for the whole run: what went out before the bridge's
    # subscription matched reaches it too, so the file must hold every number (and a
    # subscription made afresh instead of resumed would get them twice)
    pub = ros_node.create_publisher(Int32, topic, QoSProfile(
        depth=200, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    sent = 0

    def publish() -> None:
        nonlocal sent
        pub.publish(Int32(data=sent))
        sent += 1

    with LinkProxy(("127.0.0.1", bridge.port)) as proxy:
        async with roslibpy_lite.connect(f"ws://127.0.0.1:{proxy.port}", ping_interval=0.5,
                                         ping_timeout=0.5) as ros:
            states: list[ConnectionState] = []
            ros.on_state_change(states.append)
            async with Recorder(ros, path, topics={topic: "std_msgs/msg/Int32"}) as rec:

                async def tick(seconds: float) -> None:
                    for _ in range(int(seconds * 10)):
                        publish()
                        await asyncio.sleep(0.1)  # the publishing rate itself

                await tick(1.0)
                proxy.blackhole()
                await async_wait_until(lambda: ConnectionState.RECONNECTING in states, 10,
                                       "the client to notice the silent link")
                await tick(3.0)
                proxy.restore()
                await async_wait_until(lambda: ros.state is ConnectionState.CONNECTED, 20,
                                       "a reconnect")
                await tick(1.0)
                await async_wait_until(lambda: rec.stats.messages >= sent, 20,
                                       f"{sent} messages recorded")
    stats = rec.stats
    assert stats.files == [path] and stats.error is None and stats.dropped == 0
    assert len(stats.gaps) == 1 and 0 < stats.gaps[0] < 20, stats.gaps
    numbers = [decoded.data for _, _, _, decoded in _theirs(path)]
    # every number once; those from before the gap on, in order (what went out before the
    # bridge's first subscription matched may come after the first live one, from the
    # writer's history, when the bridge re-subscribes transient local)
    assert sorted(numbers) == list(range(sent)), numbers
    assert numbers[-40:] == list(range(sent - 40, sent))
    with path.open("rb") as f:
        metadata = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
    assert float(metadata["roslibpy_lite"]["gaps_s"]) == pytest.approx(stats.gaps[0], abs=1e-3)
    assert f"1 gap(s) {stats.gaps[0]:.1f} s" in stats.line()


async def test_a_recording_split_by_size_loses_nothing_between_files(
    bridge: BridgeProcess, ros_node: Any, topic: str, tmp_path: Path
) -> None:
    """``split_size``: run.mcap, run_1.mcap, ... each a complete file of its own, closed once
    it holds the limit; together they hold every image once, in order."""
    from sensor_msgs.msg import Image as RosImage

    pub = ros_node.create_publisher(RosImage, topic, 100)
    size = len(_image(0).data)
    path = tmp_path / "run.mcap"
    published = 0

    def publish() -> None:
        nonlocal published
        pub.publish(_image(published))
        published += 1

    async with (roslibpy_lite.connect(bridge.url) as ros,
                Recorder(ros, path, topics={topic: "sensor_msgs/msg/Image"},
                         split_size=10 * size, max_messages=45) as rec):
        await _until(lambda: rec.stats.messages >= 45, publish, "45 images recorded")
    stats = rec.stats
    assert stats.messages == 45 and stats.error is None
    assert stats.files == [path] + [tmp_path / f"run_{i}.mcap" for i in range(1, 5)]
    frames: list[str] = []
    for file in stats.files:
        about = info(file)
        assert about.complete and about.messages == (10 if file != stats.files[-1] else 5)
        frames += [decoded.header.frame_id for _, _, _, decoded in _theirs(file)]
    numbers = [int(name.removeprefix("cam")) for name in frames]
    assert numbers == list(range(numbers[0], numbers[0] + 45))


def test_the_blocking_client_records_and_plays(bridge: BridgeProcess, ros_node: Any,
                                               topic: str, tmp_path: Path) -> None:
    """``sync.bag.Recorder`` on ``sync.connect``: what rclpy publishes is recorded; the file
    plays back through the bridge (``sync.bag.play``) into a real rclpy subscriber."""
    path = tmp_path / "sync.mcap"
    pub = ros_node.create_publisher(Int32, topic, 100)
    with sync.connect(bridge.url) as ros:
        with sync_bag.Recorder(ros, path, topics=[topic], max_messages=20) as rec:
            count = 0
            while rec.stats.messages < 20:  # publishing until the bridge has matched
                pub.publish(Int32(data=count))
                count += 1
                rec.wait(0.02)
        assert rec.stats.messages == 20 and rec.stats.error is None
        recorded = [m.decode().data for m in sync_bag.read(path)]  # type: ignore[attr-defined]
        assert recorded == list(range(recorded[0], recorded[0] + 20))
        heard: list[int] = []
        lock = threading.Lock()

        def on_back(msg: Int32) -> None:
            with lock:
                heard.append(msg.data)

        ros_node.create_subscription(Int32, topic, on_back, 100)
        with ros.advertise(topic, "std_msgs/msg/Int32") as warm:  # play shares it, matched
            deadline = time.monotonic() + 30
            while not heard:
                assert time.monotonic() < deadline, "rclpy never heard the bridge's publisher"
                warm.publish({"data": -1})
                time.sleep(0.02)  # discovery has no event to await
            stats = sync_bag.play(ros, path, rate=4.0)
            wait_until(lambda: len(heard) >= 20 + heard.count(-1), 10,
                       "20 played messages in rclpy")
    assert stats.messages == 20
    with lock:
        assert [n for n in heard if n != -1] == recorded


def test_the_blocking_mock_records_what_the_code_under_test_publishes(tmp_path: Path) -> None:
    """``sync.MockRos`` with ``sync.bag.Recorder``: the file reads back typed."""
    path = tmp_path / "unit.mcap"
    with sync.MockRos() as ros:
        with sync_bag.Recorder(ros, path, topics={"/count": "std_msgs/msg/Int32"}) as rec:
            pub = ros.advertise("/count", "std_msgs/msg/Int32")
            for i in range(5):
                pub.publish({"data": i})
            ros.drain()
        assert rec.stats.messages == 5
    assert [m.decode().data for m in read(path)] == [0, 1, 2, 3, 4]  # type: ignore[attr-defined]
