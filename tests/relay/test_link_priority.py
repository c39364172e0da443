"""Small messages never wait behind big ones on a robot's link (issue 49, item 4).

A 640x480 camera at 10 Hz, a 10 Hz counter and a 100 Hz IMU on one robot, all watched
through a relay, the robot's link through :class:`~bench.linkproxy.LinkProxy` at 50 ms
round trip and 2 MB/s (the camera alone would need 9 MB/s): the counter and the IMU keep
their pace, and the camera gets what the link has left, in whole frames.
"""

from __future__ import annotations

import asyncio
import re
import time
from collections.abc import Callable
from typing import Any

import pytest

import roslibpy_lite
from bridge_server.zenoh.priority import (
    MEDIUM_MESSAGE,
    SMALL_MESSAGE,
    Priorities,
    TopicPriority,
    parse_overrides,
)
from tests.relay.link_load import CAMERA, COUNT, IMU, gaps, load_tier, p99
from tests.relay.support import until

pytestmark = pytest.mark.timeout(180)

IMU_BOUND = 0.25
"""Seconds: the IMU's gap p99 (1,000 gaps in 10 s). The issue's target for both topics is
150 ms; measured 70-170 ms with priorities (the machine at load 2 to 18), 460-500 ms with
every topic at one priority."""

COUNT_BOUND = 0.6
"""Seconds: the counter's gap p99 (100 gaps: one late message makes it). Measured 130-140 ms
at a light load and up to 550 ms at load 18 with priorities; 0.83-1.46 s at one priority."""


async def _paces(*robot_options: str, seconds: float = 10.0) -> dict[str, list[float]]:
    """Arrival times at our client of the counter, the IMU and the camera for ``seconds``
    through the shaped link, the robot given ``robot_options``."""
    with load_tier(*robot_options, imu=True, camera=True) as t:
        t.link.set_latency(0.025)  # each way: 50 ms round trip
        t.link.set_bandwidth(2_000_000)
        got: dict[str, list[float]] = {COUNT: [], IMU: [], CAMERA: []}

        def timed(topic: str) -> Callable[[Any], None]:
            return lambda _msg: got[topic].append(time.monotonic())

        async with roslibpy_lite.connect(t.url) as ros:
            ros.subscribe(COUNT, "std_msgs/msg/String", timed(COUNT), queue_length=1000)
            ros.subscribe(IMU, "sensor_msgs/msg/Imu", timed(IMU), queue_length=1000)
            ros.subscribe(CAMERA, "sensor_msgs/msg/Image", timed(CAMERA), raw=True,
                          queue_length=1)
            await until(lambda: all(got.values()), "every topic to arrive", 30)
            start = time.monotonic()
            await asyncio.sleep(seconds)
            return {topic: [x for x in times if x >= start] for topic, times in got.items()}


async def test_a_counter_and_an_imu_keep_their_pace_beside_a_camera() -> None:
    """Through 2 MB/s at 50 ms RTT beside a 10 Hz 640x480 camera, the 100 Hz IMU's and the
    10 Hz counter's gaps stay under their bounds at p99, every counter message arrives, and
    whole camera frames still do (the link carries about two a second)."""
    got = await _paces()
    count, imu = p99(gaps(got[COUNT])), p99(gaps(got[IMU]))
    assert imu < IMU_BOUND and count < COUNT_BOUND, (count, imu)
    assert len(got[COUNT]) >= 95, len(got[COUNT])
    assert len(got[CAMERA]) >= 5, len(got[CAMERA])


def test_a_topics_class_comes_from_its_largest_message_and_its_qos() -> None:
    """Small messages go first, a big topic last; a topic's class only ever goes down (a
    smaller message later keeps it), a best-effort topic of middle size goes one lower,
    and a big topic's messages are bulk (put whole by their own thread)."""
    p = Priorities()
    assert p.of("/count", 12) == TopicPriority("data_high")
    assert p.of("/scan", SMALL_MESSAGE + 1) == TopicPriority("data")
    assert p.of("/cloud", SMALL_MESSAGE + 1, reliable=False) == TopicPriority("data_low")
    assert p.of("/camera", MEDIUM_MESSAGE + 1, reliable=False) == TopicPriority(
        "data_low", bulk=True)
    assert p.of("/camera", 10) == TopicPriority("data_low", bulk=True)
    assert p.of("/count", MEDIUM_MESSAGE + 1).bulk
    p.forget("/count")
    assert p.of("/count", 12) == TopicPriority("data_high")
    assert p.chosen() == {"/camera": "data_low", "/cloud": "data_low", "/count": "data_high",
                          "/scan": "data"}


def test_the_robots_override_fixes_a_topics_priority() -> None:
    """``--relay-priority /odom=interactive_high+express`` fixes /odom's priority whatever
    its size; ``*=data`` every other topic's (a big one is still bulk)."""
    p = Priorities(parse_overrides(["/odom=interactive_high+express", "*=data"]))
    assert p.of("/odom", 10) == TopicPriority("interactive_high", express=True)
    assert p.of("/count", 12) == TopicPriority("data")
    assert p.of("/camera", MEDIUM_MESSAGE + 1) == TopicPriority("data", bulk=True)


@pytest.mark.parametrize("value", ["/odom", "odom=data", "/odom=fast", "/odom=data+slow", "="])
def test_a_bad_override_is_refused_naming_it(value: str) -> None:
    """A ``--relay-priority`` that is not TOPIC=LEVEL[+express] is refused naming the value
    and the levels."""
    with pytest.raises(ValueError, match=re.escape(f"--relay-priority '{value}'") + ".*data_high"):
        parse_overrides([value])
