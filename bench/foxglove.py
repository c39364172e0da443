"""Foxglove clients against rosbridge cbor-raw clients on one bridge (``--scenario foxglove``).

Both paths send the CDR bytes as ROS delivered them; they differ in framing (Foxglove's
13-byte binary header against a CBOR ``publish`` op) and in what the client does to
subscribe. In one run, on one bridge, each measured alone:

- ``image``: 640x480 rgb8 Images at the publisher's pace (as fast as it goes, the ``image``
  scenario's publisher) to one client: frames that came in order per second of publishing,
  and the bridge's CPU per frame;
- ``small``: small std_msgs/String at rising rates to one client: the highest rate with
  >= 99 % delivered, and the bridge's CPU per message there;
- ``viewers``: one 30 Hz camera to 10 clients at once: frames each got, and the bridge's
  CPU per published frame (all 10 copies) and per delivered one.

Clients are raw websocket connections (``foxglove.websocket.v1`` for the Foxglove ones)
that count frames and read each image's sequence number without decoding. Nothing here
asserts anything about time.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import time
from collections.abc import Awaitable, Callable
from typing import Any

from websockets.asyncio.client import ClientConnection, connect
from websockets.typing import Subprotocol

from bench.harness import (
    IMAGE_GRACE,
    IMAGE_PUBLISHER,
    Bridge,
    Ctx,
    close_clients,
    frame_seq,
    send_op,
    ws_open,
)
from bench.viewers import cpu_seconds

__all__ = ["foxglove"]

PATHS = ("foxglove", "cbor-raw")
VIEWERS = 10
_sub_ids = itertools.count(1)


async def _client(bridge: Bridge, path: str, topic: str, type_name: str) -> ClientConnection:
    """A client subscribed to ``topic`` on ``path``; a Foxglove one waits for the channel
    (the topic's publisher must exist)."""
    if path == "cbor-raw":
        ws = await ws_open(bridge.url)
        await send_op(ws, {"op": "subscribe", "topic": topic, "type": type_name,
                           "compression": "cbor-raw"})  # the default queue, as Foxglove's
        return ws
    ws = await connect(bridge.url, subprotocols=[Subprotocol("foxglove.websocket.v1")],
                       max_size=None, compression=None, open_timeout=10, max_queue=1024)
    deadline = time.monotonic() + 30
    while True:
        frame = await asyncio.wait_for(ws.recv(), max(deadline - time.monotonic(), 0.01))
        if isinstance(frame, str):
            op = json.loads(frame)
            found = [c for c in op.get("channels", []) if c["topic"] == topic]
            if op["op"] == "advertise" and found:
                await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                    {"id": next(_sub_ids), "channelId": found[0]["id"]}]}))
                return ws


class _Count:
    """Frames of one client: how many, and how many of a numbered stream came in order."""

    def __init__(self) -> None:
        self.frames = 0
        self.in_order = 0
        self.last = -1
        self.t_last = time.monotonic()

    def feed(self, frame: str | bytes) -> None:

        if not isinstance(frame, bytes):
            return  # status and advertise ops
        self.frames += 1
        self.t_last = time.monotonic()
        seq = frame_seq(frame)
        if seq is not None and seq > self.last:
            self.in_order += 1
            self.last = seq


async def _with_clients(
    ctx: Ctx, bridge: Bridge, path: str, topic: str, type_name: str, n: int,
    publisher: list[str], body: Callable[[Any, list[_Count]], Awaitable[dict[str, Any]]],
) -> dict[str, Any]:
    """Start the publisher, connect ``n`` clients on ``path``, run ``body(pub, counts)``."""
    pub = await ctx.ros("publish", "--topic", topic, *publisher, "--wait-subs", "1").start()
    sockets = [await _client(bridge, path, topic, type_name) for _ in range(n)]
    counts = [_Count() for _ in sockets]

    async def reader(ws: ClientConnection, count: _Count) -> None:
        with contextlib.suppress(Exception):
            async for frame in ws:
                count.feed(frame)

    tasks = [asyncio.create_task(reader(ws, c)) for ws, c in zip(sockets, counts, strict=True)]
    try:
        return await body(pub, counts)
    finally:
        await pub.close()
        await close_clients(sockets, tasks)


async def _settle(counts: list[_Count], want: int, limit: float = 10.0) -> None:
    """Until every client has ``want`` frames or none came for a second (``limit`` at most)."""
    start = time.monotonic()
    while min(c.frames for c in counts) < want and time.monotonic() - start < limit:
        if time.monotonic() - max(max(c.t_last for c in counts), start) > 1.0:
            return
        await asyncio.sleep(0.02)


async def _image(ctx: Ctx, bridge: Bridge, path: str) -> dict[str, Any]:

    async def body(pub: Any, counts: list[_Count]) -> dict[str, Any]:
        await pub.event("matched")
        cpu0 = cpu_seconds([bridge.pid])
        done = await pub.event("done", ctx.duration + 30)
        await _settle(counts, done["sent"], IMAGE_GRACE)
        cpu = cpu_seconds([bridge.pid]) - cpu0
        c = counts[0]
        return {"frames_per_s": round(c.in_order / done["elapsed"], 1), "in_order": c.in_order,
                "frames": c.frames, "published": done["sent"],
                "bridge_cpu_ms_per_frame": round(1e3 * cpu / max(c.frames, 1), 2)}

    return await _with_clients(ctx, bridge, path, f"/bench/fox_image_{_slug(path)}",
                               "sensor_msgs/msg/Image", 1,
                               [*IMAGE_PUBLISHER, "--duration", str(ctx.duration)], body)


async def _small(ctx: Ctx, bridge: Bridge, path: str) -> dict[str, Any]:
    ladder = ([5000, 10000, 20000, 30000] if ctx.quick
              else [5000, 10000, 15000, 20000, 25000, 30000, 40000])
    steps: list[dict[str, Any]] = []
    best = 0
    for rate in ladder:
        async def body(pub: Any, counts: list[_Count], rate: int = rate) -> dict[str, Any]:
            await pub.event("matched")
            cpu0 = cpu_seconds([bridge.pid])
            done = await pub.event("done", ctx.duration + 30)
            await _settle(counts, done["sent"])
            cpu = cpu_seconds([bridge.pid]) - cpu0
            got = counts[0].frames
            return {"target_rate": rate, "publisher_rate": round(done["rate"]),
                    "sent": done["sent"], "received": got,
                    "delivered_pct": round(100.0 * got / max(done["sent"], 1), 2),
                    "bridge_cpu_us_per_msg": round(1e6 * cpu / max(got, 1), 1)}

        step = await _with_clients(
            ctx, bridge, path, f"/bench/fox_small_{_slug(path)}_{rate}", "std_msgs/msg/String",
            1, ["--rate", str(rate), "--duration", str(ctx.duration), "--settle", "0.3",
                "--depth", "1000", "--linger", "3"], body)
        steps.append(step)
        if step["delivered_pct"] < 99.0:
            break
        best = max(best, step["publisher_rate"])
    return {"best_rate_99pct": best, "steps": steps}


async def _viewers(ctx: Ctx, bridge: Bridge, path: str) -> dict[str, Any]:
    async def body(pub: Any, counts: list[_Count]) -> dict[str, Any]:
        await pub.event("matched")
        cpu0 = cpu_seconds([bridge.pid])
        done = await pub.event("done", ctx.duration + 30)
        await _settle(counts, done["sent"], 3.0)
        cpu = cpu_seconds([bridge.pid]) - cpu0
        delivered = sum(c.frames for c in counts)
        return {"published": done["sent"], "per_viewer": [c.frames for c in counts],
                "bridge_cpu_ms_per_published_frame": round(1e3 * cpu / max(done["sent"], 1), 2),
                "bridge_cpu_ms_per_delivered_frame": round(1e3 * cpu / max(delivered, 1), 3),
                "bridge_cpu_pct": round(100.0 * cpu / max(done["elapsed"], 1e-3), 1)}

    return await _with_clients(
        ctx, bridge, path, f"/bench/fox_camera_{_slug(path)}", "sensor_msgs/msg/Image", VIEWERS,
        ["--kind", "image", "--rate", "30", "--depth", "5", "--settle", "0.3",
         "--duration", str(ctx.duration)], body)


def _slug(path: str) -> str:
    return path.replace("-", "_")


async def foxglove(ctx: Ctx) -> dict[str, Any]:
    """The ``foxglove`` scenario (see the module docstring)."""
    bridge = await ctx.bridge().start()
    out: dict[str, Any] = {}
    try:
        for name, part in (("image", _image), ("small", _small), ("viewers", _viewers)):
            out[name] = {path: await part(ctx, bridge, path) for path in PATHS}
    finally:
        await bridge.stop()
    out["viewers"]["count"] = VIEWERS
    out["viewers"]["camera_hz"] = 30
    return out
