"""Point clouds to several clients (``--scenario pointcloud``): a 4 MiB sensor_msgs/PointCloud2
(262,144 points of x, y, z, intensity) at 10 Hz to 5 websocket clients at once, as CBOR and
as cbor-raw (10 s, 5 with ``--quick``). Reported per encoding: the frames each client got
against those published, the bridge's CPU (% of one core) and its RSS (start, peak, end).

Clients are raw websocket connections that read each frame's sequence number from the
message header and decode nothing else. Nothing here asserts anything about time.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from typing import Any

from bench.harness import Ctx, close_clients, send_op, ws_open

__all__ = ["pointcloud"]

TOPIC = "/bench_cloud"
CLIENTS = 5


def _seq(frame: bytes | str) -> int | None:
    """The sequence number in ``header.frame_id`` of a CBOR or cbor-raw publish frame."""
    import cbor2

    if not isinstance(frame, bytes):
        return None
    op = cbor2.loads(frame)
    msg = op.get("msg") if op.get("op") == "publish" else None
    if not isinstance(msg, dict):
        return None
    raw = msg.get("bytes")
    if isinstance(raw, bytes):  # CDR: encapsulation 4, stamp 8, then frame_id (length, text)
        n = int.from_bytes(raw[12:16], "little")
        return int(raw[16:16 + n - 1].split(b" ", 1)[0])
    return int(msg["header"]["frame_id"].split(" ", 1)[0])


async def _run(ctx: Ctx, compression: str, seconds: float) -> dict[str, Any]:
    import psutil

    bridge = await ctx.bridge().start()
    proc = psutil.Process(bridge.pid)
    sockets = [await ws_open(bridge.url) for _ in range(CLIENTS)]
    got: list[set[int]] = [set() for _ in sockets]

    async def reader(i: int) -> None:
        with contextlib.suppress(Exception):
            async for frame in sockets[i]:
                seq = _seq(frame)
                if seq is not None:
                    got[i].add(seq)

    readers = [asyncio.create_task(reader(i)) for i in range(CLIENTS)]
    rss: list[float] = []
    try:
        for ws in sockets:
            await send_op(ws, {"op": "subscribe", "topic": TOPIC,
                               "type": "sensor_msgs/msg/PointCloud2", "queue_length": 20,
                               "compression": compression})
        start_rss = proc.memory_info().rss
        pub = await ctx.ros("publish", "--topic", TOPIC, "--kind", "cloud", "--rate", "10",
                            "--duration", str(seconds), "--depth", "20", "--settle", "0.5",
                            "--linger", "3").start()
        await pub.event("matched")
        t0 = time.monotonic()
        cpu0 = proc.cpu_times()
        done_task = asyncio.create_task(pub.event("done", seconds + 60))
        while not done_task.done():  # sample the bridge's memory while the clouds flow
            rss.append(proc.memory_info().rss)
            await asyncio.wait({done_task}, timeout=0.1)
        sent = done_task.result()["sent"]
        deadline = time.monotonic() + 15
        while min(len(g) for g in got) < sent and time.monotonic() < deadline:
            rss.append(proc.memory_info().rss)
            await asyncio.sleep(0.1)  # the last clouds in flight; bounded
        cpu1 = proc.cpu_times()
        wall = time.monotonic() - t0
        await pub.close()
        end_rss = proc.memory_info().rss
    finally:
        await close_clients(sockets, readers)
        await bridge.stop()
    mb = 1024 * 1024
    busy = cpu1.user - cpu0.user + cpu1.system - cpu0.system
    return {
        "published": sent,
        "per_client": [len(g) for g in got],
        "all_delivered": all(len(g) == sent for g in got),
        "bridge_cpu_pct": round(100.0 * busy / wall, 1),
        "bridge_rss_mb": {"start": round(start_rss / mb, 1),
                          "peak": round(max(rss, default=start_rss) / mb, 1),
                          "end": round(end_rss / mb, 1)},
        "out_mib_per_s": round(CLIENTS * sent * 4 / wall, 1),
    }


async def pointcloud(ctx: Ctx) -> dict[str, Any]:
    """The ``pointcloud`` scenario (see the module docstring)."""
    seconds = 5.0 if ctx.quick else 10.0
    return {"cloud_mib": 4, "rate_hz": 10, "clients": CLIENTS,
            **{comp: await _run(ctx, comp, seconds) for comp in ("cbor", "cbor-raw")}}
