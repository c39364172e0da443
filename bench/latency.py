"""One-way ROS -> client latency of stamped strings at 200 Hz (``latency``), and ours beside
rosbridge_server_rs on one stream (``latency_side_by_side``)."""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from typing import Any

from websockets.asyncio.client import ClientConnection

from bench.harness import Bridge, Ctx, close_clients, percentile, send_op, ws_open


async def _read_stamped(ws: ClientConnection, lat: list[float], skip: int) -> None:
    """Collect the one-way latency (ms) of every stamped message with a number >= ``skip``."""
    with contextlib.suppress(Exception):
        async for frame in ws:
            now = time.monotonic_ns()
            op = json.loads(frame)
            if op.get("op") == "publish":
                seq, stamp = op["msg"]["data"].split(" ")
                if int(seq) >= skip:  # skip warm-up
                    lat.append((now - int(stamp)) / 1e6)


def _quantiles_ms(lat: list[float]) -> dict[str, Any]:
    return {
        "measured": len(lat),
        "p50_ms": round(percentile(lat, 0.5), 3),
        "p90_ms": round(percentile(lat, 0.9), 3),
        "p99_ms": round(percentile(lat, 0.99), 3),
        "max_ms": round(max(lat), 3) if lat else None,
    }


async def latency(ctx: Ctx) -> dict[str, Any]:
    """One-way ROS -> client latency at 200 Hz (monotonic stamp in the message, same machine)."""
    topic = "/bench/latency"
    bridge = await ctx.bridge().start()
    ws = await ws_open(bridge.url)
    await send_op(ws, {"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String"})
    lat: list[float] = []
    rtask = asyncio.create_task(_read_stamped(ws, lat, 20))
    # the same stream straight to an rclpy subscriber process first: the ROS side's own share
    base = await ctx.ros("subscribe", "--topic", "/bench/latency_base", "--stamped", "--idle",
                         "1.0", "--duration", str(ctx.duration + 20)).start()
    bpub = await ctx.ros("publish", "--topic", "/bench/latency_base", "--kind", "stamp",
                         "--rate", "200", "--duration", str(ctx.duration), "--settle",
                         "0.3").start()
    await bpub.event("done", ctx.duration + 30)
    baseline = (await base.event("done", 30)).get("latency_ms")
    await bpub.close()
    await base.close()
    try:
        pub = await ctx.ros("publish", "--topic", topic, "--kind", "stamp", "--rate", "200",
                            "--duration", str(ctx.duration), "--settle", "0.3").start()
        done = await pub.event("done", ctx.duration + 30)
        await asyncio.sleep(0.2)
        await pub.close()
    finally:
        await ws.close()
        rtask.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await rtask
        await bridge.stop()
    return {
        "rate_hz": 200,
        "sent": done["sent"],
        **_quantiles_ms(lat),
        "rclpy_to_rclpy_ms": baseline,
    }


async def latency_side_by_side(ctx: Ctx) -> dict[str, Any]:
    """``latency`` for our bridge and rosbridge_server_rs in one run, on one stream.

    One rclpy publisher sends each stamped message to the next of their topics in turn
    (and of a plain rclpy subscriber's), 200 Hz to each: whatever state the machine is in
    (single-server runs move by 2x from one run to the next here) is the same for all of
    them. With ``--bridge-root`` that checkout runs beside this one as a third server.
    """
    servers = {"ours": Bridge(ctx.domain, ctx.bridge_args),
               "rosbridge_server_rs": Bridge(ctx.domain, peer="rs")}
    if ctx.bridge_root:
        servers[f"ours@{ctx.bridge_root}"] = Bridge(ctx.domain, ctx.bridge_args, ctx.bridge_root)
    topics = {name: f"/bench/latency_{k}" for k, name in enumerate(servers)}
    lats: dict[str, list[float]] = {name: [] for name in servers}
    skip = 20 * (len(servers) + 1)  # the first 20 messages of each topic warm up
    sockets: list[ClientConnection] = []
    tasks: list[asyncio.Task[None]] = []
    base = None
    try:
        for name, bridge in servers.items():
            await bridge.start()
            ws = await ws_open(bridge.url)
            sockets.append(ws)
            await send_op(ws, {"op": "subscribe", "topic": topics[name],
                               "type": "std_msgs/msg/String"})
            tasks.append(asyncio.create_task(_read_stamped(ws, lats[name], skip)))
        duration = ctx.duration * 3
        base = await ctx.ros("subscribe", "--topic", "/bench/latency_base", "--stamped", "--idle",
                             "1.0", "--duration", str(duration + 20)).start()
        topic_args = [a for t in (*topics.values(), "/bench/latency_base") for a in ("--topic", t)]
        pub = await ctx.ros("publish", *topic_args, "--kind", "stamp",
                            "--rate", str(200 * (len(servers) + 1)), "--duration", str(duration),
                            "--settle", "0.3").start()
        done = await pub.event("done", duration + 30)
        await asyncio.sleep(0.2)
        await pub.close()
        baseline = (await base.event("done", 30)).get("latency_ms")
    finally:
        if base is not None:
            await base.close()
        await close_clients(sockets, tasks)
        for bridge in servers.values():
            await bridge.stop()
    return {
        "rate_hz_each": 200,
        "sent": done["sent"],
        **{name: _quantiles_ms(lat) for name, lat in lats.items()},
        "rclpy_to_rclpy_ms": baseline,
    }
