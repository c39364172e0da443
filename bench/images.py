"""640x480 images to one client as JSON, CBOR and cbor-raw beside the ROS ceiling (``image``)."""

from __future__ import annotations

import json
import time
from typing import Any

from bench.ceiling import image_ceiling
from bench.counting import InOrder, drain_until
from bench.harness import FRAME_SEQ_BYTES, IMAGE_GRACE, IMAGE_PUBLISHER, Ctx, frame_seq
from bench.profiler import Profiler
from bench.viewers import cpu_seconds, open_viewer


async def image(ctx: Ctx) -> dict[str, Any]:
    """640x480 rgb8 Images to one client as JSON, CBOR and cbor-raw (the CDR bytes as they came
    from ROS), beside the ROS ceiling; the publisher is :data:`IMAGE_PUBLISHER` throughout.

    ``frames_per_s`` is the frames that reached the client in order, divided by the publishing
    time: the same measure for every server (``--peer``, ``--bridge-root``) and for the ceiling.
    Frames still on their way when the publisher stops count if they come within
    :data:`IMAGE_GRACE` of its last (the ceiling's the same way).
    """
    ceiling = await image_ceiling(ctx)
    out: dict[str, Any] = {"ros_ceiling": ceiling}
    for compression in ("none", "cbor", "cbor-raw"):
        topic = f"/bench/image_{compression.replace('-', '_')}"
        bridge = await ctx.bridge().start()
        stream = InOrder()
        sizes: list[int] = []

        def on_frame(prefix: bytes, size: int, stream: InOrder = stream,
                     sizes: list[int] = sizes) -> None:
            seq = frame_seq(prefix)
            stream.feed(seq)
            if not sizes and seq is not None:
                sizes.append(size)

        # the client reads each frame's first bytes (the number is in them) and skips the
        # rest: a websockets client spent about as much CPU per frame as the bridge, on a
        # machine where the publisher, the bridge and the client share two cores
        viewer = await open_viewer(bridge.url, json.dumps(
            {"op": "subscribe", "topic": topic, "type": "sensor_msgs/msg/Image",
             "compression": compression, "queue_length": 5}), FRAME_SEQ_BYTES, on_frame)
        profile = None
        try:
            pub = await ctx.ros("publish", "--topic", topic, *IMAGE_PUBLISHER, "--duration",
                                str(ctx.duration)).start()
            await pub.event("matched")
            cpu0 = cpu_seconds([bridge.pid])
            prof = None
            if ctx.profile:
                prof = Profiler(bridge.pid, ctx.duration)
                await prof.start()
            done = await pub.event("done", ctx.duration + 30)
            cutoff = done["t_end"] + IMAGE_GRACE
            await drain_until(stream, done["sent"], idle=IMAGE_GRACE,
                               limit=cutoff - time.monotonic())
            cpu = cpu_seconds([bridge.pid]) - cpu0
            await pub.close()
            if prof is not None:
                profile = await prof.result()
        finally:
            viewer.close()
            await bridge.stop()
        key = "json" if compression == "none" else compression
        in_order = stream.in_order_by(cutoff)
        out[key] = {"frames_per_s": round(in_order / done["elapsed"], 1),
                    "ros_ceiling_fps": ceiling["frames_per_s"],
                    "in_order": in_order, "frames": stream.frames,
                    "other_frames": stream.other,
                    "published": done["sent"], "publish_s": round(done["elapsed"], 2),
                    "bridge_cpu_ms_per_frame": round(1e3 * cpu / max(stream.frames, 1), 2),
                    "frame_bytes": sizes[0] if sizes else None}
        if profile is not None:
            out[key]["profile"] = profile
    return out
