"""Recording across a dropped link and into split files, and the blocking client's bag API,
against the real bridge and checked with the independent reader (mcap-ros2-support)."""

from __future__ import annotations

import asyncio
import contextlib
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
    pub = ros_node.create_publisher(Int32, topic, QoSProfile(  # type: ignore[no-untyped-call]
        depth=200, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    sent = 0

    def publish() -> None:
        nonlocal sent
        pub.publish(Int32(data=sent))
        sent += 1

    with LinkProxy(("127.0.0.1", bridge.port)) as proxy:
        # a keepalive a loaded machine's stall of a second or two does not trip (a second
        # gap), still quick to notice the blackhole
        async with roslibpy_lite.connect(f"ws://127.0.0.1:{proxy.port}", ping_interval=1.0,
                                         ping_timeout=3.0) as ros:
            states: list[ConnectionState] = []
            ros.on_state_change(states.append)
            async with Recorder(ros, path, topics={topic: "std_msgs/msg/Int32"}) as rec:

                async def tick(seconds: float) -> None:
                    for _ in range(int(seconds * 10)):
                        publish()
                        await asyncio.sleep(0.1)  # the publishing rate itself

                await tick(1.0)
                proxy.blackhole()
                await async_wait_until(lambda: ConnectionState.RECONNECTING in states, 20,
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
            began = time.monotonic()
            stats = sync_bag.play(ros, path, rate=4.0)
            took = time.monotonic() - began
            wait_until(lambda: len(heard) >= 20 + heard.count(-1), 10,
                       "20 played messages in rclpy")
    assert stats.messages == 20
    assert took >= info(path).duration / 4.0 - 1e-3, took  # the recorded timing, 4x as fast
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


def test_the_cli_reports_the_file_size_and_records_the_publishers_qos(
    bridge: BridgeProcess, ros_node: Any, topic: str, tmp_path: Path
) -> None:
    """`bag record` of a latched topic: its last line and `bag info` give the file's size
    on disk in the same words; the channel carries rosbag2's offered_qos_profiles (YAML, the
    keys and words rosbag2 writes) saying transient local."""
    import subprocess
    import sys

    import yaml
    from std_msgs.msg import String

    from roslibpy_lite.bag._mcap import format_size

    pub = ros_node.create_publisher(
        String, topic, QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))  # type: ignore[no-untyped-call]
    pub.publish(String(data="kept"))
    path = tmp_path / "latched.mcap"

    def cli(*argv: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, "-m", "roslibpy_lite.cli", *argv],
                              capture_output=True, text=True, timeout=60)

    rec = cli("bag", "record", topic, "-o", str(path), "--max", "1", "-q", "--url", bridge.url)
    assert rec.returncode == 0, rec
    # the message's CDR: a 4-byte header, the length, "kept" and its NUL, padded to 4
    size = format_size(path.stat().st_size)
    assert f"1 topics, 1 msgs, 16 B of messages ({size} on disk)" in rec.stdout, rec.stdout
    shown = cli("bag", "info", str(path))
    assert f"Size:      {size}\n" in shown.stdout, shown
    with path.open("rb") as f:
        channels = list(make_reader(f).get_summary().channels.values())  # type: ignore[union-attr]
    profiles = yaml.safe_load(channels[0].metadata["offered_qos_profiles"])
    assert len(profiles) == 1 and set(profiles[0]) == {
        "history", "depth", "reliability", "durability", "deadline", "lifespan", "liveliness",
        "liveliness_lease_duration", "avoid_ros_namespace_conventions"}
    assert profiles[0]["durability"] == "transient_local"
    assert profiles[0]["reliability"] == "reliable"
    assert set(profiles[0]["deadline"]) == {"sec", "nsec"}


async def test_our_recording_of_a_latched_topic_plays_latched(
    bridge: BridgeProcess, ros_node: Any, topic: str, tmp_path: Path
) -> None:
    """A latched topic recorded by us plays latched without being named in latch=: a
    transient-local rclpy subscriber made once the rclpy publisher is gone gets the value."""
    from std_msgs.msg import String

    from roslibpy_lite.bag import play

    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)  # type: ignore[no-untyped-call]
    pub = ros_node.create_publisher(String, topic, latched)
    pub.publish(String(data="kept"))
    later = ros_node.create_publisher(String, f"{topic}_later", 10)
    path = tmp_path / "run.mcap"
    async with roslibpy_lite.connect(bridge.url) as ros:
        async with Recorder(ros, path, topics=[topic, f"{topic}_later"]) as rec:
            await async_wait_until(lambda: rec.stats.per_topic.get(topic) == 1,
                                   what="the latched message recorded")
            while not rec.stats.per_topic.get(f"{topic}_later"):  # until matched (discovery)
                later.publish(String(data="later"))
                await asyncio.sleep(0.05)
        ros_node.destroy_publisher(pub)
        await async_wait_until(lambda: ros_node.count_publishers(topic) == 0,
                               what="the rclpy publisher gone")
        # played 1000 times slower: the "later" message waits while the subscriber comes
        playing = asyncio.ensure_future(play(ros, path, rate=0.001))
        try:
            await async_wait_until(lambda: ros_node.count_publishers(topic) == 1,
                                   what="the player's publisher")
            got: list[str] = []
            ros_node.create_subscription(String, topic, lambda m: got.append(m.data), latched)
            await async_wait_until(lambda: got == ["kept"], timeout=10,
                                   what="the played latched message")
        finally:
            playing.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await playing


@pytest.mark.parametrize(("n", "shown"), [
    (0, "0 B"), (999, "999 B"), (1000, "1.0 kB"), (18_500, "18.5 kB"), (999_949, "999.9 kB"),
    (999_950, "1.0 MB"), (3_200_000, "3.2 MB"), (1_500_000_000, "1.5 GB"),
    (2_000_000_000_000, "2000.0 GB"),
])
def test_sizes_are_shown_in_the_unit_that_fits(n: int, shown: str) -> None:
    """One formatter for record and info: bytes up to 999, then kB, MB, GB (powers of 1000)."""
    from roslibpy_lite.bag._mcap import format_size

    assert format_size(n) == shown
