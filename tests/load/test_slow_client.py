"""A client that stops reading costs the bridge bounded memory and delays nobody else."""

from __future__ import annotations

import asyncio
import contextlib
import json
from typing import Any

import cbor2
import psutil
import pytest
from sensor_msgs.msg import Image
from std_msgs.msg import String

from tests.bridge.support import wait_subscribers
from tests.helpers import ros_image, roundtrip
from tests.load.support import StalledClient, qos

pytestmark = pytest.mark.asyncio

IMAGES = 500
RATE_HZ = 100
MB = 1024 * 1024
BOUND_MB = 300  # 500 images of 0.9 MB kept for the stalled client would be ~440 MB


class Flood:
    """What one image flood with a stalled client showed: RSS growth and what the others got."""

    def __init__(self) -> None:
        self.growth_mb = 0.0
        self.frames: set[int] = set()
        self.numbers: list[int] = []
        self.notes: list[Any] = []


async def _flood(make_bridge: Any, ws_connect: Any, ros_node: Any, topic: str) -> Flood:
    """Stall one client on an image topic, flood it at 100 Hz with a string topic alongside."""
    bridge = make_bridge()
    assert bridge.proc is not None
    rss = psutil.Process(bridge.proc.pid).memory_info
    images, strings = f"{topic}/image", f"{topic}/other"
    out = Flood()
    stalled = await asyncio.to_thread(StalledClient, bridge.port)
    try:
        stalled.send({"op": "subscribe", "topic": images, "type": "sensor_msgs/msg/Image"})
        early = await asyncio.to_thread(stalled.sync)  # from here on it never reads again
        assert early == []
        reader = await ws_connect(bridge.url)
        await reader.send({"op": "subscribe", "topic": images, "type": "sensor_msgs/msg/Image",
                           "compression": "cbor", "queue_length": IMAGES})
        other = await ws_connect(bridge.url)
        await other.send({"op": "subscribe", "topic": strings, "type": "std_msgs/msg/String",
                          "queue_length": IMAGES})
        await roundtrip(reader)
        await roundtrip(other)
        image_pub = ros_node.create_publisher(Image, images, qos(depth=IMAGES))
        string_pub = ros_node.create_publisher(String, strings, qos(depth=IMAGES))
        await wait_subscribers(image_pub)
        await wait_subscribers(string_pub)
        loop = asyncio.get_running_loop()
        last = [loop.time()]

        async def read_images() -> None:
            with contextlib.suppress(Exception):
                async for frame in reader.ws:
                    op = cbor2.loads(frame) if isinstance(frame, bytes) else json.loads(frame)
                    if op.get("op") == "publish":
                        out.frames.add(int(op["msg"]["header"]["frame_id"]))
                        last[0] = loop.time()
                    else:
                        out.notes.append(op)

        async def read_strings() -> None:
            with contextlib.suppress(Exception):
                async for frame in other.ws:
                    op = json.loads(frame)
                    if op.get("op") == "publish":
                        out.numbers.append(int(op["msg"]["data"]))
                        last[0] = loop.time()
                    else:
                        out.notes.append(op)

        tasks = [asyncio.create_task(read_images()), asyncio.create_task(read_strings())]
        msg = ros_image(640, 480, "rgb8", bytes(range(256)) * (640 * 480 * 3 // 256))
        start = peak = rss().rss
        try:
            for i in range(IMAGES):
                msg.header.frame_id = str(i)
                image_pub.publish(msg)
                string_pub.publish(String(data=str(i)))
                peak = max(peak, rss().rss)
                await asyncio.sleep(1 / RATE_HZ)  # pacing the flood, not synchronisation
            # drain: until both readers have everything, or nothing came for 4 s (a sample
            # lost in transport at the end of a burst is repaired only at the writer's next
            # heartbeat, 3 s by default in Fast DDS)
            deadline = loop.time() + 12
            while (len(out.numbers) < IMAGES or len(out.frames) < IMAGES) and (
                loop.time() < deadline and loop.time() - last[0] < 4.0
            ):
                peak = max(peak, rss().rss)
                await asyncio.sleep(0.05)
        finally:
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
    finally:
        stalled.close()
    out.growth_mb = (peak - start) / MB
    return out


_floods: dict[str, Flood] = {}


async def _the_flood(make_bridge: Any, ws_connect: Any, ros_node: Any, topic: str) -> Flood:
    """The module's one flood: both tests below check what the same flood showed (run once)."""
    if "flood" not in _floods:
        _floods["flood"] = await _flood(make_bridge, ws_connect, ros_node, topic)
    return _floods["flood"]


async def test_stalled_client_bounded_memory_and_same_topic_reader_served(
    make_bridge: Any, ws_connect: Any, ros_node: Any, topic: str
) -> None:
    """Under a 640x480 image flood a client that never reads grows the bridge by < 300 MB, and a reading client on the same topic still gets most frames (>= 80 %; a bridge blocked by the stalled socket would deliver only a handful)."""
    flood = await _the_flood(make_bridge, ws_connect, ros_node, topic)
    assert flood.growth_mb < BOUND_MB, f"bridge RSS grew {flood.growth_mb:.0f} MB"
    assert len(flood.frames) >= 0.8 * IMAGES, (
        f"reader on the same topic got {len(flood.frames)} of {IMAGES}; statuses {flood.notes[:3]}"
    )


async def test_stalled_client_and_flood_cost_another_topic_nothing(
    make_bridge: Any, ws_connect: Any, ros_node: Any, topic: str
) -> None:
    """During the same flood a client subscribed to another 100 Hz topic receives every message, in order."""
    flood = await _the_flood(make_bridge, ws_connect, ros_node, topic)
    assert flood.numbers == list(range(IMAGES)), (
        f"other topic: got {len(flood.numbers)} of {IMAGES}, missing "
        f"{sorted(set(range(IMAGES)) - set(flood.numbers))[:20]}; statuses {flood.notes[:3]}"
    )


async def test_queue_length_keeps_the_newest_for_a_stalled_client(
    bridge: Any, ws_connect: Any, ros_node: Any, topic: str
) -> None:
    """A client that stops reading, then resumes, loses the oldest messages beyond its queue_length, keeps the newest, in order, and is warned about the drops."""
    total, queue_length, pad = 100, 5, "x" * 200_000  # 20 MB in all: far beyond socket buffers
    stalled = await asyncio.to_thread(StalledClient, bridge.port)
    try:
        stalled.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String",
                      "queue_length": queue_length})
        assert await asyncio.to_thread(stalled.sync) == []  # subscribed; now it stops reading
        witness = await ws_connect()
        await witness.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String",
                            "queue_length": total})
        await roundtrip(witness)
        pub = ros_node.create_publisher(String, topic, qos(depth=total))
        await wait_subscribers(pub)
        for i in range(total):
            pub.publish(String(data=f"{i}:{pad}"))
        # the bridge fans each message out to both clients at once: when the witness has the
        # last one, the stalled client's queue has seen every message too
        await witness.expect(lambda op: op["msg"]["data"].startswith(f"{total - 1}:"),
                             op="publish", timeout=15)

        def read_until_last() -> tuple[list[int], list[Any]]:
            seqs: list[int] = []
            others: list[Any] = []
            while not seqs or seqs[-1] != total - 1:
                op = stalled.read_op()
                if op.get("op") == "publish":
                    seqs.append(int(op["msg"]["data"].split(":", 1)[0]))
                else:
                    others.append(op)
            return seqs, others

        seqs, others = await asyncio.to_thread(read_until_last)
    finally:
        stalled.close()
    tail = list(range(total - queue_length, total))
    assert seqs[-queue_length:] == tail, f"the newest {queue_length} must survive: {seqs}"
    assert seqs == sorted(set(seqs)), f"in order, no repeats: {seqs}"
    assert len(seqs) < total, "nothing was dropped: the stall did not fill the buffers"
    drops = [op for op in others if op.get("op") == "status" and "dropped" in op.get("msg", "")]
    assert drops, f"no drop warning among {others}"
    assert drops[0]["level"] == "warning"
    assert topic in drops[0]["msg"] and f"queue_length {queue_length}" in drops[0]["msg"]
