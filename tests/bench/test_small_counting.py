"""The small-message figures (ros_to_client) count numbered Strings from each frame's first
bytes, as a counting viewer reads them, in JSON and in cbor-raw."""

from __future__ import annotations

import json
import os

import pytest

from bench.counting import SINK_PREFIX, Sink
from bench.harness import Bridge, RosSide
from bench.viewers import open_viewer
from tests.helpers import async_wait_until


@pytest.mark.parametrize("compression", ["none", "cbor-raw"])
async def test_the_sink_counts_every_string_a_real_bridge_sends(compression: str) -> None:
    """A counting viewer of a real bridge feeding a Sink counts each of 200 numbered Strings
    (bench/ros_side.py's publisher) once, and a status op as none."""
    domain = int(os.environ["ROS_DOMAIN_ID"])
    topic = "/bench_test/counted_strings"
    bridge = await Bridge(domain).start()
    sink = Sink(300)
    read: list[bytes] = []

    def on_frame(prefix: bytes, size: int) -> None:
        read.append(prefix)
        sink.feed(prefix, size)

    viewer = await open_viewer(bridge.url, json.dumps(
        {"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String",
         "queue_length": 1000, "compression": compression}), SINK_PREFIX, on_frame)
    try:
        pub = await RosSide(domain, "publish", "--topic", topic, "--count", "200", "--rate",
                            "1000", "--wait-subs", "1", "--settle", "0.3").start()
        try:
            done = await pub.event("done", 60)
            await async_wait_until(lambda: sink.unique == done["sent"] == 200, 20.0,
                                   "every String counted")
        finally:
            await pub.close()
        viewer.send(json.dumps({"op": "publish", "msg": {}}))  # answered with a status op
        await async_wait_until(lambda: len(read) == 201, 10.0, "the status op read")
    finally:
        viewer.close()
        await bridge.stop()
    assert sink.frames == sink.unique == 200
    assert b'"op":"status"' in read[-1]
