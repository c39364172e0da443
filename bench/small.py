"""Small messages through the bridge, both ways: the highest rate of std_msgs/String with
>= 99 % delivered, on a ladder of rates (``ros_to_client``, ``ros_to_client_raw``,
``client_to_ros``)."""

from __future__ import annotations

import asyncio
import json
from typing import Any

from bench.counting import SINK_PREFIX, Sink, drain_until
from bench.harness import Ctx, send_op, ws_open
from bench.profiler import Profiler
from bench.viewers import cpu_seconds, open_viewer


def _rates(ctx: Ctx, full: list[int], quick: list[int]) -> list[int]:
    return quick if ctx.quick else full


async def ros_to_client(ctx: Ctx, compression: str = "none") -> dict[str, Any]:
    """Step search: highest ROS -> client rate of small strings with >= 99 % delivered, on a
    ladder to 40,000 msg/s (``compression``: as the client subscribes); the client is a
    counting viewer (:class:`Sink`)."""
    topic = "/bench/r2c"
    bridge = await ctx.bridge().start()
    queue_length = 1000
    current: list[Sink] = [Sink(1)]
    # a counting viewer: a websockets client decoding each frame cost the harness as much
    # CPU as the bridge, and at 30,000 a second the machine's two cores lacked it
    viewer = await open_viewer(bridge.url, json.dumps(
        {"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String",
         "queue_length": queue_length, "id": "r2c", "compression": compression}),
        SINK_PREFIX, lambda prefix, size: current[0].feed(prefix, size))
    steps: list[dict[str, Any]] = []
    best = 0
    profile: dict[str, Any] | None = None
    d = ctx.duration
    try:
        # up to the harness publisher's own ceiling (36,000-40,000 a second here), in JSON too
        ladder = _rates(ctx, [5000, 10000, 15000, 20000, 25000, 30000, 35000, 40000],
                        [5000, 10000, 15000, 20000, 30000, 40000])
        for rate in ladder:
            current[0] = sink = Sink(int(rate * d * 1.5) + 100)
            cpu0 = cpu_seconds([bridge.pid])
            pub = await ctx.ros("publish", "--topic", topic, "--rate", str(rate), "--duration",
                                str(d), "--settle", "0.3", "--linger", "3").start()
            await pub.event("matched")
            prof = None
            if ctx.profile and rate >= 4000:  # keep the profile of the last step run
                prof = Profiler(bridge.pid, d)
                await prof.start()
            done = await pub.event("done", d + 30)
            await drain_until(sink, done["sent"])
            cpu = cpu_seconds([bridge.pid]) - cpu0
            await pub.close()
            if prof is not None:
                profile = {"at_rate": rate, **(await prof.result())}
            pct = 100.0 * sink.unique / max(done["sent"], 1)
            steps.append({"target_rate": rate, "publisher_rate": round(done["rate"]),
                          "sent": done["sent"], "received": sink.unique,
                          "delivered_pct": round(pct, 2),
                          "bridge_cpu_us_per_msg": round(1e6 * cpu / max(sink.unique, 1), 1)})
            if pct >= 99.0:
                best = max(best, round(done["rate"]))
            else:
                break
    finally:
        viewer.close()
        await bridge.stop()
    out: dict[str, Any] = {"best_rate_99pct": best, "queue_length": queue_length, "steps": steps}
    if profile is not None:
        out["profile"] = profile
    return out


async def client_to_ros(ctx: Ctx) -> dict[str, Any]:
    """Step search: highest client -> ROS rate of small strings with >= 99 % delivered."""
    topic = "/bench/c2r"
    bridge = await ctx.bridge().start()
    ws = await ws_open(bridge.url)
    await send_op(ws, {"op": "advertise", "topic": topic, "type": "std_msgs/msg/String",
                       "queue_size": 1000})
    steps: list[dict[str, Any]] = []
    best = 0
    d = ctx.duration
    loop = asyncio.get_running_loop()
    try:
        for rate in _rates(ctx, [2000, 5000, 8000, 10000, 12000, 15000, 20000],
                           [2000, 5000, 10000, 15000]):
            n = int(rate * d)
            sub = await ctx.ros("subscribe", "--topic", topic, "--expect", str(n), "--idle", "1.0",
                                "--duration", str(d + 20)).start()
            await sub.event("matched")
            await asyncio.sleep(0.3)  # let discovery settle both ways (reliable, volatile)
            cpu0 = cpu_seconds([bridge.pid])
            t0 = loop.time()
            for i in range(n):
                due = t0 + i / rate
                ahead = due - loop.time()
                if ahead > 0.001:
                    await asyncio.sleep(ahead)
                await ws.send(f'{{"op":"publish","topic":"{topic}","msg":{{"data":"{i}"}}}}')
            sent_rate = n / (loop.time() - t0)
            got = await sub.event("done", d + 40)
            cpu = cpu_seconds([bridge.pid]) - cpu0
            await sub.close()
            pct = 100.0 * int(got["unique"]) / n
            steps.append({"target_rate": rate, "client_send_rate": round(sent_rate), "sent": n,
                          "received": got["unique"], "ros_receive_rate": round(got["rate"]),
                          "delivered_pct": round(pct, 2),
                          "bridge_cpu_us_per_msg": round(1e6 * cpu / max(int(got["unique"]), 1),
                                                         1)})
            if pct >= 99.0:
                best = max(best, round(min(sent_rate, rate)))
            else:
                break
    finally:
        await ws.close()
        await bridge.stop()
    return {"best_rate_99pct": best, "steps": steps}
