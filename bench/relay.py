"""The robot's uplink with many viewers (``--scenario relay_uplink``): through a relay, and
straight to the robot's bridge.

A 640x480 rgb8 camera (random pixels, as incompressible as a real one) at 10 Hz, watched by
1, 10, 50 and 100 websocket viewers (1 and 10 with ``--quick``), each subscribed with
``cbor-raw``. Two set-ups, one after the other:

- **relay**: the robot's bridge without a websocket listener dials out to a relay that is
  the Zenoh router (``--no-websocket --zenoh-connect``); the viewers connect to the relay
  (``ws://relay/robot``). The robot's Zenoh link goes through a counting TCP proxy
  (:class:`~bench.linkproxy.LinkProxy`): its bytes are the robot's uplink.
- **direct**: the viewers connect to the robot's bridge through the same kind of proxy:
  its bytes are what the robot sends them.

Reported per set-up and number of viewers: the uplink in MiB (and MiB/s), and per
published frame as a multiple of one viewer's; the frames each viewer got against those
published (min and median); the relay's and the robot bridge's CPU (% of one core). The
viewers run in processes of their own and count frames without decoding them
(``bench/viewers.py``); on a 2-core machine they, the relay and the robot share the cores,
so delivered frames may fall with many viewers for want of CPU; the uplink bytes do not
depend on that. Nothing here asserts anything about time.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import re
import statistics
import time
from typing import Any

from bench.harness import READY, Bridge, Ctx, percentile, send_op, ws_open
from bench.linkproxy import LinkProxy
from bench.ports import free_port

__all__ = ["relay_dead_link", "relay_imu", "relay_outage", "relay_service", "relay_uplink"]

TOPIC = "/bench_camera"
ROBOT = "benchbot"
RATE_HZ = 10
FRAME_BYTES = 640 * 480 * 3
RELAY_READY = re.compile(r"relay listening on wss?://([\d.]+):(\d+)")
ROBOT_READY = re.compile(r"robot \S+ dialing out to Zenoh")


async def _watch(ctx: Ctx, url: str, n: int, link: LinkProxy, pids: dict[str, int],
                 seconds: float) -> dict[str, Any]:
    """Subscribe ``n`` viewers at ``url``, publish the camera, count what crossed ``link``.
    The viewers run in processes of their own and count frames without decoding them
    (:class:`bench.viewers.ViewerPool`)."""
    import psutil

    from bench.viewers import ViewerPool

    pool = await ViewerPool(url, n, {"op": "subscribe", "topic": TOPIC,
                                     "type": "sensor_msgs/msg/Image",
                                     "compression": "cbor-raw", "queue_length": 2}).start()
    procs = {name: psutil.Process(pid) for name, pid in pids.items()}
    try:
        pub = await ctx.ros("publish", "--topic", TOPIC, "--kind", "image", "--noise",
                            "--rate", str(RATE_HZ), "--duration", str(seconds), "--depth", "5",
                            "--settle", "0.5", "--linger", "2").start()
        await pub.event("matched", 60)
        before = link.bytes_forwarded
        cpu0 = {name: p.cpu_times() for name, p in procs.items()}
        t0 = time.monotonic()
        sent = (await pub.event("done", seconds + 60))["sent"]
        deadline = time.monotonic() + 5
        while True:  # the last frames in flight; bounded
            got = (await pool.counts())["frames"]
            if min(got) >= sent or time.monotonic() > deadline:
                break
            await asyncio.sleep(0.1)
        wall = time.monotonic() - t0
        uplink = link.bytes_forwarded - before
        cpu1 = {name: p.cpu_times() for name, p in procs.items()}
        await pub.close()
    finally:
        await pool.close()
    cpu = {f"{name}_cpu_pct": round(100.0 * (cpu1[name].user - cpu0[name].user
                                            + cpu1[name].system - cpu0[name].system) / wall, 1)
           for name in procs}
    return {
        "viewers": n,
        "published": sent,
        "frames_per_viewer": {"min": min(got), "median": statistics.median(got)},
        "uplink_mib_per_s": round(uplink / wall / 2**20, 2),
        "uplink_mib": round(uplink / 2**20, 1),
        **cpu,
    }


async def _through_relay(ctx: Ctx, counts: tuple[int, ...], seconds: float) -> list[dict[str, Any]]:
    router_port = free_port()
    relay = Bridge(ctx.domain, ["--zenoh-listen", f"tcp/127.0.0.1:{router_port}"],
                   ctx.bridge_root, module="bridge_server.zenoh.relay", ready=RELAY_READY)
    await relay.start()
    results = []
    try:
        with LinkProxy(("127.0.0.1", router_port)) as link:
            robot = Bridge(ctx.domain, ["--no-websocket", "--robot", ROBOT, "--zenoh-connect",
                                        f"tcp/127.0.0.1:{link.port}"], ctx.bridge_root,
                           ready=ROBOT_READY)
            await robot.start()
            try:
                url = f"ws://127.0.0.1:{relay.port}/{ROBOT}"
                for n in counts:
                    results.append(await _watch(ctx, url, n, link,
                                                {"relay": relay.pid, "robot": robot.pid},
                                                seconds))
            finally:
                await robot.stop()
    finally:
        await relay.stop()
    return results


async def _direct(ctx: Ctx, counts: tuple[int, ...], seconds: float) -> list[dict[str, Any]]:
    bridge = await ctx.bridge().start()
    results = []
    try:
        with LinkProxy(("127.0.0.1", bridge.port)) as link:
            for n in counts:
                results.append(await _watch(ctx, f"ws://127.0.0.1:{link.port}", n, link,
                                            {"robot": bridge.pid}, seconds))
    finally:
        await bridge.stop()
    return results


def _with_ratio(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Each row's uplink bytes per published frame as a multiple of one viewer's (per frame,
    not per second: with many viewers the last frames take longer to drain)."""
    def per_frame(r: dict[str, Any]) -> float:
        return float(r["uplink_mib"]) / max(int(r["published"]), 1)

    one = per_frame(rows[0]) or float("nan")
    return [{**r, "x_one_viewer": round(per_frame(r) / one, 2)} for r in rows]


async def relay_uplink(ctx: Ctx) -> dict[str, Any]:
    """The ``relay_uplink`` scenario (see the module docstring)."""
    counts = (1, 10) if ctx.quick else (1, 10, 50, 100)
    seconds = 4.0 if ctx.quick else 8.0
    return {
        "camera": f"640x480 rgb8 at {RATE_HZ} Hz ({FRAME_BYTES / 2**20:.2f} MiB a frame)",
        "relay": _with_ratio(await _through_relay(ctx, counts, seconds)),
        "direct": _with_ratio(await _direct(ctx, counts, seconds)),
    }


@contextlib.asynccontextmanager
async def _tier(ctx: Ctx, relays: int = 1, robot_listens: bool = False
                ) -> Any:
    """``relays`` relays (the first the Zenoh router, the others its clients) and a robot
    dialing out to the first; yields (the relays, the robot's bridge)."""
    router = f"tcp/127.0.0.1:{free_port()}"
    started: list[Bridge] = []
    try:
        for i in range(relays):
            zenoh = ["--zenoh-listen", router] if i == 0 else ["--zenoh-connect", router]
            relay = Bridge(ctx.domain, zenoh, ctx.bridge_root, module="bridge_server.zenoh.relay",
                           ready=RELAY_READY)
            started.append(await relay.start())
        robot = Bridge(ctx.domain, [*([] if robot_listens else ["--no-websocket"]), "--robot",
                                    ROBOT, "--zenoh-connect", router], ctx.bridge_root,
                       ready=READY if robot_listens else ROBOT_READY)
        started.append(await robot.start())
        yield started[:relays], robot
    finally:
        for b in reversed(started):
            await b.stop()


async def relay_service(ctx: Ctx) -> dict[str, Any]:
    """``relay_service``: call_service round trips to an rclpy SetBool service through a
    relay and straight to the robot's bridge, in alternating blocks of 100 sequential calls
    (whatever the machine does meanwhile, both see it): p50/p99 of each."""
    name = "/bench/relay_srv"
    blocks = 3 if ctx.quick else 10
    lat: dict[str, list[float]] = {"relay": [], "direct": []}
    srv = await ctx.ros("serve", "--service", name, "--duration", "600").start()
    try:
        await srv.event("ready")
        async with _tier(ctx, robot_listens=True) as (relays, robot):
            sockets = {"relay": await _viewers_at(_url(relays[0])),
                       "direct": await _viewers_at(robot.url)}
            try:
                for ws in sockets.values():  # the first call of each waits for discovery
                    await _call_until_answered(ws, name)
                for _ in range(blocks):
                    for way, ws in sockets.items():
                        for _ in range(100):
                            t = time.perf_counter_ns()
                            await _call(ws, name)
                            lat[way].append((time.perf_counter_ns() - t) / 1e6)
            finally:
                for ws in sockets.values():
                    await ws.close()
    finally:
        await srv.close()
    return {way: {"calls": len(v), "p50_ms": round(percentile(v, 0.5), 3),
                  "p99_ms": round(percentile(v, 0.99), 3)} for way, v in lat.items()}


def _url(relay: Bridge) -> str:
    return f"ws://127.0.0.1:{relay.port}/{ROBOT}"


async def _viewers_at(url: str) -> Any:
    deadline = time.monotonic() + 30
    while True:
        try:
            return await ws_open(url)
        except Exception:
            if time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.2)


async def _call(ws: Any, service: str) -> dict[str, Any]:
    await send_op(ws, {"op": "call_service", "service": service, "type": "std_srvs/srv/SetBool",
                       "args": {"data": True}, "id": "c"})
    while True:
        op = json.loads(await ws.recv())
        if op.get("op") == "service_response":
            return dict(op)


async def _call_until_answered(ws: Any, service: str) -> None:
    deadline = time.monotonic() + 30
    while (reply := await _call(ws, service)).get("result") is not True:
        if time.monotonic() > deadline:
            raise RuntimeError(f"{service} never answered: {reply}")
        await asyncio.sleep(0.2)


async def relay_imu(ctx: Ctx) -> dict[str, Any]:
    """``relay_imu``: a 100 Hz sensor_msgs/Imu to 200 JSON viewers spread over two relays (50
    with ``--quick``): the fraction delivered, the latency from the rclpy publisher's stamp to
    the decoding viewers (p50/p99, ms), and the relays' CPU per message delivered. The
    viewers run in processes of their own and count frames without decoding them
    (:class:`bench.viewers.ViewerPool`; the first of each process decodes and times them)."""
    from bench.viewers import ViewerPool, cpu_seconds

    viewers = 50 if ctx.quick else 200
    seconds = 5.0 if ctx.quick else 10.0
    topic = f"/bench_imu_{os.getpid()}"
    subscribe = {"op": "subscribe", "topic": topic, "type": "sensor_msgs/msg/Imu",
                 "queue_length": 100}
    async with _tier(ctx, relays=2) as (relays, _robot):
        pools = [await ViewerPool(_url(relay), viewers // 2, subscribe, processes=2).start()
                 for relay in relays]
        try:
            pub = await ctx.ros("publish", "--topic", topic, "--kind", "imu", "--rate", "100",
                                "--duration", str(seconds), "--depth", "100", "--settle", "0.5",
                                "--linger", "2").start()
            await pub.event("matched", 60)
            pids = [r.pid for r in relays]
            cpu0 = cpu_seconds(pids)
            sent = int((await pub.event("done", seconds + 60))["sent"])
            deadline = time.monotonic() + 5
            while True:  # the last messages in flight; bounded
                counts = [await pool.counts() for pool in pools]
                got = [f for c in counts for f in c["frames"]]
                if min(got) >= sent or time.monotonic() > deadline:
                    break
                await asyncio.sleep(0.2)
            busy = cpu_seconds(pids) - cpu0
            await pub.close()
        finally:
            for pool in pools:
                await pool.close()
    delivered = sum(got)
    lat = [x for c in counts for x in c["latencies_ms"]]
    return {
        "viewers": viewers, "relays": 2, "rate_hz": 100, "published": sent,
        "delivered_fraction": round(delivered / (sent * viewers), 4) if sent else None,
        "latency_p50_ms": round(percentile(lat, 0.5), 3),
        "latency_p99_ms": round(percentile(lat, 0.99), 3),
        "relay_cpu_us_per_message": round(1e6 * busy / delivered, 1) if delivered else None,
    }


async def _presence(ws: Any, words: str, timeout: float = 60.0) -> None:
    """Read ``ws`` until a ``status`` op containing ``words`` arrives."""
    async with asyncio.timeout(timeout):
        while True:
            op = json.loads(await ws.recv())
            if op.get("op") == "status" and words in op.get("msg", ""):
                return


async def relay_dead_link(ctx: Ctx) -> dict[str, Any]:
    """``relay_dead_link``: how long a relay takes to tell its clients that a robot's link
    died. The robot dials the relay (the Zenoh router) through a TCP proxy; a viewer of the
    robot through the relay asks for ``info`` statuses; the proxy then drops every byte both
    ways (a cut cable, no FIN), and the time to the viewer's "went away" status is taken; the
    link is restored and the "is back" status awaited; repeated. With the default lease
    (``--zenoh-lease 3``) and with Zenoh's own default (10 s), for comparison."""
    rounds = 2 if ctx.quick else 4
    results: dict[str, Any] = {}
    for lease in (3.0, 10.0):
        lease_args = ["--zenoh-lease", f"{lease:g}"]
        zport = free_port()
        relay = Bridge(ctx.domain, ["--zenoh-listen", f"tcp/127.0.0.1:{zport}", *lease_args],
                       ctx.bridge_root, module="bridge_server.zenoh.relay", ready=RELAY_READY)
        await relay.start()
        noticed: list[float] = []
        back: list[float] = []
        try:
            with LinkProxy(("127.0.0.1", zport)) as link:
                robot = Bridge(ctx.domain, ["--no-websocket", "--robot", ROBOT, "--zenoh-connect",
                                            f"tcp/127.0.0.1:{link.port}", *lease_args],
                               ctx.bridge_root, ready=ROBOT_READY)
                await robot.start()
                try:
                    ws = await _viewers_at(_url(relay))
                    try:
                        await send_op(ws, {"op": "set_level", "level": "info"})
                        for _ in range(rounds):
                            link.blackhole()
                            cut = time.perf_counter()
                            await _presence(ws, "went away")
                            noticed.append(time.perf_counter() - cut)
                            link.restore()
                            restored = time.perf_counter()
                            await _presence(ws, "is back")
                            back.append(time.perf_counter() - restored)
                    finally:
                        await ws.close()
                finally:
                    await robot.stop()
        finally:
            await relay.stop()
        results[f"lease_{lease:g}s"] = {
            "noticed_s": [round(x, 2) for x in noticed],
            "noticed_max_s": round(max(noticed), 2),
            "back_s": [round(x, 2) for x in back]}
    return results


OUTAGE_TOPIC = "/bench_outage"


async def _robot_rss_and_window(pid: int, metrics_url: str) -> tuple[float, int]:
    """The robot's RSS (MiB) and the payload bytes its replay window holds (its /metrics)."""
    import urllib.request

    import psutil

    rss = psutil.Process(pid).memory_info().rss / 2**20

    def window() -> int:
        with urllib.request.urlopen(metrics_url, timeout=5) as reply:
            text = reply.read().decode()
        return int(sum(float(line.rpartition(" ")[2]) for line in text.splitlines()
                       if line.startswith("roslibpy_bridge_relay_replay_bytes{")))

    return rss, await asyncio.to_thread(window)


async def relay_outage(ctx: Ctx) -> dict[str, Any]:
    """``relay_outage``: a robot's Zenoh link blackholed (no FIN) for 5, 15 and 60 s (5 and
    15 with ``--quick``) while a reliable 10 Hz topic flows to a viewer through the relay,
    with the default replay window (300 messages, 8 MiB): per outage, the messages published
    meanwhile, those lost (never delivered), the seconds from the link's restore to the last
    message published during the outage being delivered, and the robot's RSS and replay
    window bytes during the outage (sampled each 0.5 s)."""
    outages = (5.0, 15.0) if ctx.quick else (5.0, 15.0, 60.0)
    zport, mport = free_port(), free_port()
    relay = Bridge(ctx.domain, ["--zenoh-listen", f"tcp/127.0.0.1:{zport}"], ctx.bridge_root,
                   module="bridge_server.zenoh.relay", ready=RELAY_READY)
    await relay.start()
    got: list[tuple[int, int, int]] = []  # (received, number, published), monotonic ns
    results: list[dict[str, Any]] = []
    try:
        with LinkProxy(("127.0.0.1", zport)) as link:
            robot = Bridge(ctx.domain, ["--no-websocket", "--robot", ROBOT, "--zenoh-connect",
                                        f"tcp/127.0.0.1:{link.port}", "--metrics-port",
                                        str(mport)], ctx.bridge_root, ready=ROBOT_READY)
            await robot.start()
            pub = None
            ws = await _viewers_at(_url(relay))
            try:
                await send_op(ws, {"op": "subscribe", "topic": OUTAGE_TOPIC,
                                   "type": "std_msgs/msg/String", "queue_length": 5000})

                async def reader() -> None:
                    with contextlib.suppress(Exception):
                        async for frame in ws:
                            op = json.loads(frame)
                            if op.get("op") == "publish":
                                n, sent = op["msg"]["data"].split()
                                got.append((time.monotonic_ns(), int(n), int(sent)))

                reading = asyncio.create_task(reader())
                total = sum(outages) + 30 * len(outages) + 30
                pub = await ctx.ros("publish", "--topic", OUTAGE_TOPIC, "--kind", "stamp",
                                    "--rate", "10", "--duration", str(total), "--depth", "10",
                                    "--linger", "0").start()
                await pub.event("matched", 60)
                for seconds in outages:
                    results.append(await _one_outage(link, seconds, got, robot.pid,
                                                     f"http://127.0.0.1:{mport}/metrics"))
                reading.cancel()
            finally:
                await ws.close()
                if pub is not None:
                    await pub.close()
                await robot.stop()
    finally:
        await relay.stop()
    return {"rate_hz": 10, "window": "300 messages, 8 MiB (the defaults)",
            "outages": results}


async def _one_outage(link: LinkProxy, seconds: float, got: list[tuple[int, int, int]],
                      robot_pid: int, metrics_url: str) -> dict[str, Any]:
    """Cut the link for ``seconds``, restore it, and measure (see :func:`relay_outage`)."""
    deadline = time.monotonic() + 60
    while not got or got[-1][0] < time.monotonic_ns() - 500_000_000:  # messages flow
        if time.monotonic() > deadline:
            raise RuntimeError("the viewer hears nothing from the robot")
        await asyncio.sleep(0.1)
    rss0, window0 = await _robot_rss_and_window(robot_pid, metrics_url)
    peak_rss, peak_window = rss0, window0
    link.blackhole()
    cut = time.monotonic_ns()
    end = time.monotonic() + seconds
    while time.monotonic() < end:  # the outage itself: its length is what is measured
        rss, window = await _robot_rss_and_window(robot_pid, metrics_url)
        peak_rss, peak_window = max(peak_rss, rss), max(peak_window, window)
        await asyncio.sleep(0.5)
    link.restore()
    restored = time.monotonic_ns()
    deadline = time.monotonic() + 60
    while not got or got[-1][2] < restored + 2_000_000_000:  # live messages again
        if time.monotonic() > deadline:
            raise RuntimeError("the robot's messages did not come back")
        await asyncio.sleep(0.1)
    before = max(n for _, n, sent in got if sent < cut)
    after = min(n for _, n, sent in got if sent >= restored)
    during = set(range(before + 1, after))
    heard = {n for _, n, _ in got}
    late = [t for t, n, sent in got if n in during]
    return {
        "outage_s": seconds,
        "published_during": len(during),
        "lost": len(during - heard),
        "duplicates": len(got) - len(heard),
        "recover_s": round((max(late) - restored) / 1e9, 2) if late else None,
        "robot_rss_mib": {"before": round(rss0, 1), "peak": round(peak_rss, 1)},
        "window_bytes": {"before": window0, "peak": peak_window},
    }
