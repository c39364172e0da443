"""Real links (``--scenario links``): a silent link and a slow one, through bench/linkproxy.py.

- ``blackhole``: a client subscribed through the proxy; the link goes silent (no FIN, no
  RST). Reported: seconds until the client leaves CONNECTED and until the bridge drops the
  client's ROS subscription, with this version's keepalive (2 + 3 s) and with the
  keepalive figures of the previous release (websockets' 20 + 20 s), cut off at 30 s.
- ``slow_link``: a 640x480 rgb8 camera at 30 Hz to a client over a 2 Mbit/s link,
  ``queue_length`` 1, CBOR; reported: the age of the frames the client gets (p50 per third
  of the run), with the kernel's unsent bytes bounded (``--notsent-lowat``, the default) and
  left to the kernel (``--notsent-lowat 0``, the previous behaviour). A fresh stream keeps
  the age flat; a stale one grows.
- ``resume``: 10 Hz each way (client to ROS, ROS to client) across an 8 s blackhole, with
  sessions kept (``--session-keep 30``, the default) and without (``--session-keep 0``, the
  previous behaviour). Reported: how many of the numbers each side sent the other side got
  (lost, duplicated).

Nothing here asserts anything about time.
"""

from __future__ import annotations

import asyncio
import time
from typing import Any

from bench.harness import Ctx, percentile, send_op, ws_open
from bench.linkproxy import LinkProxy

__all__ = ["links"]

CUTOFF = 30.0


async def _blackhole(ctx: Ctx, interval: float, timeout: float) -> dict[str, Any]:
    """Seconds until the client and the bridge each notice a silent link."""
    import roslibpy_lite
    from roslibpy_lite.api import ConnectionState

    bridge = ctx.bridge()
    bridge.args += ["--keepalive-interval", str(interval), "--keepalive-timeout", str(timeout)]
    await bridge.start()
    ros_side = ctx.ros("publish", "--topic", "/bench_link", "--rate", "10", "--duration", "60",
                       "--wait-subs", "1")
    try:
        with LinkProxy(("127.0.0.1", bridge.port)) as proxy:
            ros = await roslibpy_lite.connect(f"ws://127.0.0.1:{proxy.port}",
                                              ping_interval=interval, ping_timeout=timeout)
            await ros.subscribe("/bench_link", "std_msgs/msg/String", lambda m: None)
            await ros_side.start()
            await ros_side.event("matched")
            start = len(bridge.lines)
            proxy.blackhole()
            t0 = time.monotonic()
            client_s = bridge_s = None
            while time.monotonic() - t0 < CUTOFF and (client_s is None or bridge_s is None):
                now = time.monotonic() - t0
                if client_s is None and ros.state is not ConnectionState.CONNECTED:
                    client_s = round(now, 2)
                if bridge_s is None and any("no sign of it" in line
                                            for line in list(bridge.lines)[start:]):
                    bridge_s = round(now, 2)
                await asyncio.sleep(0.05)
            proxy.restore()
            await ros.close()
    finally:
        await ros_side.close()
        await bridge.stop()
    return {"keepalive_s": [interval, timeout], "client_noticed_s": client_s,
            "bridge_noticed_s": bridge_s, "cutoff_s": CUTOFF}


async def _slow_link(ctx: Ctx, lowat: int, seconds: float) -> dict[str, Any]:
    """Ages of 30 Hz camera frames over a 2 Mbit/s link."""
    import cbor2

    bridge = ctx.bridge()
    bridge.args += ["--notsent-lowat", str(lowat)]
    await bridge.start()
    ros_side = ctx.ros("publish", "--topic", "/bench_cam", "--kind", "image", "--rate", "30",
                       "--duration", str(seconds + 5), "--wait-subs", "1", "--depth", "1")
    ages: list[tuple[float, float]] = []
    try:
        with LinkProxy(("127.0.0.1", bridge.port)) as proxy:
            proxy.set_bandwidth(250_000)  # 2 Mbit/s
            ws = await ws_open(f"ws://127.0.0.1:{proxy.port}")
            await send_op(ws, {"op": "subscribe", "topic": "/bench_cam", "queue_length": 1,
                               "type": "sensor_msgs/msg/Image", "compression": "cbor"})
            await ros_side.start()
            await ros_side.event("matched")
            t0 = time.monotonic()
            while time.monotonic() - t0 < seconds:
                try:
                    frame = await asyncio.wait_for(ws.recv(), seconds)
                except TimeoutError:
                    break
                got = time.monotonic_ns()
                if isinstance(frame, bytes):
                    msg = cbor2.loads(frame)["msg"]
                    sent_ns = int(msg["header"]["frame_id"].split()[1])
                    ages.append((time.monotonic() - t0, (got - sent_ns) / 1e9))
            await ws.close()
    finally:
        await ros_side.close()
        await bridge.stop()
    thirds = []
    for k in range(3):
        part = [a for t, a in ages if k * seconds / 3 <= t < (k + 1) * seconds / 3]
        thirds.append(round(percentile(part, 50), 2) if part else None)
    return {"notsent_lowat": lowat or "kernel default", "frames": len(ages),
            "age_p50_s_by_third": thirds,
            "age_max_s": round(max((a for _, a in ages), default=0.0), 2)}


async def _resume(ctx: Ctx, keep: float, hole: float = 8.0) -> dict[str, Any]:
    """Lost and duplicated messages each way across a blackhole of ``hole`` seconds."""
    import roslibpy_lite

    bridge = ctx.bridge()
    bridge.args += ["--session-keep", str(keep)]
    await bridge.start()
    up = ctx.ros("subscribe", "--topic", "/bench_up", "--duration", "60", "--idle", str(hole + 4),
                 "--expect", "100000")
    down = ctx.ros("publish", "--topic", "/bench_down", "--rate", "10", "--duration",
                   str(hole + 4), "--wait-subs", "1")
    got: list[int] = []
    sent = 0
    try:
        with LinkProxy(("127.0.0.1", bridge.port)) as proxy:
            ros = await roslibpy_lite.connect(f"ws://127.0.0.1:{proxy.port}")
            await ros.subscribe("/bench_down", "std_msgs/msg/String",
                                lambda m: got.append(int(m["data"])), queue_length=1000)
            pub = await ros.advertise("/bench_up", "std_msgs/msg/String")
            await up.start()
            await up.event("matched")
            await down.start()
            await down.event("matched")
            t0 = time.monotonic()
            holed = restored = False
            while time.monotonic() - t0 < hole + 4:
                now = time.monotonic() - t0
                if not holed and now >= 2:
                    proxy.blackhole()
                    holed = True
                if not restored and now >= 2 + hole:
                    proxy.restore()
                    restored = True
                await pub.publish({"data": str(sent)})
                sent += 1
                await asyncio.sleep(0.1)
            done_down = await down.event("done", 30)
            await asyncio.sleep(3.0)  # the last ones in flight (no event says "all arrived")
            await ros.close()
            done_up = await up.event("done", 60)
    finally:
        await up.close()
        await down.close()
        await bridge.stop()
    published = int(done_down["sent"])
    return {
        "session_keep_s": keep, "blackhole_s": hole,
        "client_to_ros": {"sent": sent, "lost": sent - int(done_up["unique"] or 0),
                          "duplicated": int(done_up["received"]) - int(done_up["unique"] or 0)},
        "ros_to_client": {"sent": published, "lost": published - len(set(got)),
                          "duplicated": len(got) - len(set(got))},
    }


async def links(ctx: Ctx) -> dict[str, Any]:
    """Blackhole detection and slow-link freshness, now and with the previous defaults."""
    seconds = 20.0 if ctx.quick else 60.0
    return {
        "blackhole_now": await _blackhole(ctx, 2.0, 3.0),
        "blackhole_previous_defaults": await _blackhole(ctx, 20.0, 20.0),
        "slow_link_now": await _slow_link(ctx, 64 * 1024, seconds),
        "slow_link_kernel_buffers": await _slow_link(ctx, 0, seconds),
        "resume_now": await _resume(ctx, 30.0),
        "resume_previous_behaviour": await _resume(ctx, 0.0),
    }
