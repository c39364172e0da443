"""The bridge's own cost: its CPU with one idle client (``idle_cpu``) and its memory while a
client that never reads is subscribed to an image flood (``memory_stall``)."""

from __future__ import annotations

import asyncio
import json
import time
from typing import Any

from bench.harness import Ctx, StalledClient, send_op, ws_open


async def idle_cpu(ctx: Ctx) -> dict[str, Any]:
    """The bridge's CPU over a few seconds with one connected (and then subscribed) client."""
    import psutil

    bridge = await ctx.bridge().start()
    proc = psutil.Process(bridge.pid)
    window = 3.0 if ctx.quick else 5.0
    ws = await ws_open(bridge.url)
    out: dict[str, Any] = {"window_s": window}
    try:
        await asyncio.sleep(1.0)
        proc.cpu_percent(None)
        await asyncio.sleep(window)
        out["connected_pct_of_core"] = round(proc.cpu_percent(None), 2)
        await send_op(ws, {"op": "subscribe", "topic": "/bench/idle",
                           "type": "std_msgs/msg/String"})
        await asyncio.sleep(1.0)
        proc.cpu_percent(None)
        await asyncio.sleep(window)
        out["subscribed_pct_of_core"] = round(proc.cpu_percent(None), 2)
        out["threads"] = proc.num_threads()
    finally:
        await ws.close()
        await bridge.stop()
    return out


async def memory_stall(ctx: Ctx) -> dict[str, Any]:
    """The bridge's RSS while a client that never reads is subscribed to an image flood."""
    import psutil

    topic = "/bench/stall"
    bridge = await ctx.bridge().start()
    proc = psutil.Process(bridge.pid)
    stalled = await asyncio.to_thread(StalledClient, bridge.port)
    stalled.send({"op": "subscribe", "topic": topic, "type": "sensor_msgs/msg/Image"})
    duration = max(ctx.duration, 4.0)
    samples: list[int] = []
    try:
        pub = await ctx.ros("publish", "--topic", topic, "--kind", "image", "--rate", "100",
                            "--duration", str(duration), "--depth", "5", "--linger", "0").start()
        await pub.event("matched")
        start = proc.memory_info().rss
        waiter = asyncio.ensure_future(pub.event("done", duration + 30))
        while not waiter.done():
            samples.append(proc.memory_info().rss)
            await asyncio.sleep(0.05)
        done = waiter.result()
        await pub.close()
        await asyncio.sleep(1.0)
        end = proc.memory_info().rss
        stalled.close()
        await asyncio.sleep(1.0)
        after_close = proc.memory_info().rss
        # the bridge still answers another client promptly
        ws = await ws_open(bridge.url)
        t = time.perf_counter()
        await send_op(ws, {"op": "call_service", "service": "/rosapi/get_ros_version", "id": "v"})
        reply = json.loads(await asyncio.wait_for(ws.recv(), 10))
        answer_ms = (time.perf_counter() - t) * 1e3
        await ws.close()
    finally:
        stalled.close()
        await bridge.stop()
    mb = 1024 * 1024
    return {
        "images_published": done["sent"],
        "publisher_rate": round(done["rate"], 1),
        "rss_start_mb": round(start / mb, 1),
        "rss_peak_mb": round(max(samples, default=start) / mb, 1),
        "rss_end_mb": round(end / mb, 1),
        "rss_after_stalled_client_left_mb": round(after_close / mb, 1),
        "growth_peak_mb": round((max(samples, default=start) - start) / mb, 1),
        "other_client_answer_ms": round(answer_ms, 2),
        "other_client_reply_ok": reply.get("result") is True,
    }
