"""The image figures count frames in order, by the number in ``header.frame_id``, in any encoding."""

from __future__ import annotations

import json
import os

import cbor2

from bench.counting import InOrder
from bench.harness import FRAME_SEQ_BYTES, Bridge, RosSide, frame_seq
from bench.viewers import open_viewer
from tests.helpers import async_wait_until

STAMP = "12 743068554089"  # "<seq> <monotonic ns>", as bench/ros_side.py publishes


def _cdr() -> bytes:
    text = STAMP.encode() + b"\0"
    return (b"\0\1\0\0" + bytes(8) + len(text).to_bytes(4, "little") + text
            + bytes(3) + (480).to_bytes(4, "little") + bytes(1000))


def test_frame_seq_in_every_encoding() -> None:
    """JSON text, CBOR and cbor-raw publish frames give their number; a status op gives none."""
    header = {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": STAMP}
    as_json = json.dumps({"op": "publish", "topic": "/bench/image_none",
                          "msg": {"header": header, "height": 480, "data": "AAEC" * 1000}})
    as_cbor = cbor2.dumps({"op": "publish", "topic": "/bench/image_cbor",
                           "msg": {"header": header, "height": 480, "data": bytes(1000)}})
    raw = cbor2.dumps({"op": "publish", "topic": "/bench/image_cbor_raw",
                       "msg": {"secs": 1, "nsecs": 2, "bytes": _cdr()}})
    status = json.dumps({"op": "status", "level": "warning",
                         "msg": "dropped 1 messages on /p (queue_length 5, 1 in all)"})
    assert [frame_seq(f) for f in (as_json, as_cbor, raw, status)] == [12, 12, 12, None]


def test_in_order_counts() -> None:
    """A late or repeated frame is a frame but not one in order; an unnumbered one is apart."""
    stream = InOrder()
    for seq in (3, 1, 4, None, 4, 5):
        stream.feed(seq)
    assert (stream.frames, stream.unique, stream.other) == (5, 3, 1)
    assert stream.in_order_by(stream.in_order_at[1]) == 2


async def test_ros_side_counts_images_in_order() -> None:
    """The ceiling's raw rclpy subscriber reads the number of every image and when it came."""
    domain = int(os.environ["ROS_DOMAIN_ID"])
    topic = "/bench_test/ceiling_image"
    sub = await RosSide(domain, "subscribe", "--kind", "image", "--topic", topic, "--depth",
                        "50", "--idle", "1.0", "--duration", "30").start()
    pub = await RosSide(domain, "publish", "--kind", "image", "--topic", topic, "--count", "30",
                        "--rate", "100", "--depth", "50", "--settle", "0.3").start()
    try:
        done = await pub.event("done", 60)
        got = await sub.event("done", 60)
    finally:
        await pub.close()
        await sub.close()
    assert done["sent"] == got["received"] == len(got["in_order_at"]) == 30
    assert got["in_order_at"] == sorted(got["in_order_at"])
    assert got["in_order_at"][-1] <= done["t_end"] + 1.0


async def test_the_image_client_reads_every_number_from_a_real_bridge() -> None:
    """The image figures' client, a viewer that reads each frame's first bytes and skips the
    rest, gets the number of every 640x480 frame a real bridge sends, in each encoding, and
    the frame's size."""
    domain = int(os.environ["ROS_DOMAIN_ID"])
    topic = "/bench_test/counted_image"
    bridge = await Bridge(domain).start()
    streams: dict[str, InOrder] = {}
    sizes: dict[str, int] = {}
    viewers = []
    try:
        for compression in ("none", "cbor", "cbor-raw"):
            stream = streams[compression] = InOrder()

            def on_frame(prefix: bytes, size: int, stream: InOrder = stream,
                         compression: str = compression) -> None:
                stream.feed(frame_seq(prefix))
                sizes[compression] = size

            # queue_length holds all 20: a viewer behind on a loaded machine gets every frame
            # late rather than losing the oldest, as the bench's viewers (5) may
            viewers.append(await open_viewer(bridge.url, json.dumps(
                {"op": "subscribe", "topic": topic, "type": "sensor_msgs/msg/Image",
                 "compression": compression, "queue_length": 20}), FRAME_SEQ_BYTES, on_frame))
        pub = await RosSide(domain, "publish", "--kind", "image", "--topic", topic, "--count",
                            "20", "--rate", "20", "--depth", "50", "--wait-subs", "1",
                            "--settle", "0.3").start()
        try:
            await pub.event("done", 60)
            try:
                await async_wait_until(lambda: all(s.unique == 20 for s in streams.values()),
                                       20.0, "every frame counted in every encoding")
            except AssertionError as exc:  # say which encoding fell short, and by how much
                counted = {c: (s.unique, s.other) for c, s in streams.items()}
                raise AssertionError(f"{exc}: (frames, other frames) by encoding {counted}"
                                     ) from None
        finally:
            await pub.close()
    finally:
        for viewer in viewers:
            viewer.close()
        await bridge.stop()
    assert {c: s.frames for c, s in streams.items()} == dict.fromkeys(streams, 20)
    assert sizes["cbor-raw"] > 640 * 480 * 3 and sizes["none"] > 640 * 480 * 4
