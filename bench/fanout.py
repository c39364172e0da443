"""What a viewer costs the server (``--scenario fanout``): one topic to many raw viewers.

The viewers run in processes of their own and count frames without decoding them
(:mod:`bench.viewers`: the first viewer of each process decodes and checks what it gets), so
100-200 viewers measure the server, not this harness. Three parts:

- **bridge**: a 50 Hz stamped ``std_msgs/String`` to 100 and 200 JSON viewers of one bridge
  (for 10 s each, 4 s with ``--quick``);
- **relay**: the same through one relay (the robot's bridge dials out to it);
- **camera_relay**: a 640x480 rgb8 camera at 10 Hz to 100 cbor-raw viewers of one relay;
- **write_floor_us**: the floor, in the same run: the CPU one thread spends per ``send`` of a
  small message's bytes to as many loopback connections (:func:`write_floor`), read by another
  process; the kernel's share of a write is most of it.

Reported per step: messages published and delivered (the fraction of published x viewers,
the viewers that missed any, min and median per viewer), the server's CPU per delivered
message in microseconds (user + system of the bridge or relay process over the step, divided
by the messages every viewer received: far less sensitive to what else the machine runs
than a rate) and the kernel's share of it (the socket writes), its CPU in % of a core, the
viewer processes' CPU, and the latency p50/p99 of the decoding viewers. Nothing here asserts anything about time.
"""

from __future__ import annotations

import asyncio
import itertools
import os
import socket
import statistics
import time
from typing import Any

from bench.harness import Bridge, Ctx, percentile
from bench.relay import _tier, _url
from bench.viewers import ViewerPool, cpu_seconds

__all__ = ["fanout"]

_steps = itertools.count()
SMALL_TOPIC = "/bench_fanout"
CAMERA_TOPIC = "/bench_fanout_camera"


async def _step(ctx: Ctx, url: str, server: Bridge, n: int, *, topic: str, kind: str,
                rate: float, seconds: float, subscribe: dict[str, Any],
                robot: Bridge | None = None) -> dict[str, Any]:
    """``n`` viewers of ``topic`` at ``url`` while a ``kind`` publisher runs ``seconds``
    (the topic's name made this step's own: no other run's publisher reaches it)."""
    topic = f"{topic}_{os.getpid()}_{next(_steps)}"
    pool = await ViewerPool(url, n, {"op": "subscribe", "topic": topic, **subscribe}).start()
    try:
        pub = await ctx.ros("publish", "--topic", topic, "--kind", kind, "--rate", str(rate),
                            "--duration", str(seconds), "--depth", "100", "--settle", "0.5",
                            "--linger", "2").start()
        await pub.event("matched", 60)
        others = {"robot": robot.pid} if robot is not None else {}
        cpu0, sys0 = cpu_seconds([server.pid]), cpu_seconds([server.pid], system=True)
        other0 = {k: cpu_seconds([pid]) for k, pid in others.items()}
        view0 = cpu_seconds(pool.pids)
        t0 = time.monotonic()
        sent = int((await pub.event("done", seconds + 60))["sent"])
        deadline = time.monotonic() + 5
        while True:  # the last messages in flight; bounded
            counts = await pool.counts()
            if min(counts["frames"]) >= sent or time.monotonic() > deadline:
                break
            await asyncio.sleep(0.2)
        wall = time.monotonic() - t0
        cpu = cpu_seconds([server.pid]) - cpu0
        kernel = cpu_seconds([server.pid], system=True) - sys0
        other = {f"{k}_cpu_pct": round(100 * (cpu_seconds([pid]) - other0[k]) / wall, 1)
                 for k, pid in others.items()}
        viewers_cpu = cpu_seconds(pool.pids) - view0
        await pub.close()
    finally:
        await pool.close()
    frames = counts["frames"]
    delivered = sum(frames)
    lat = counts["latencies_ms"]
    return {
        "viewers": n, "viewer_processes": len(pool.sizes), "published": sent,
        "delivered": delivered,
        "delivered_fraction": round(delivered / (sent * n), 4) if sent else None,
        "viewers_missing_any": sum(f < sent for f in frames),
        "frames_per_viewer": {"min": min(frames), "median": statistics.median(frames)},
        "server_cpu_us_per_message": round(1e6 * cpu / delivered, 2) if delivered else None,
        "server_system_us_per_message": (round(1e6 * kernel / delivered, 2) if delivered
                                         else None),
        "server_cpu_pct": round(100 * cpu / wall, 1),
        **other,
        "viewers_cpu_pct": round(100 * viewers_cpu / wall, 1),
        "checked": counts["checked"], "out_of_order": counts["out_of_order"],
        "missed_by_a_decoding_viewer": sorted(set(range(sent)) - set(counts["seqs"]))[:20],
        "latency_p50_ms": round(percentile(lat, 0.5), 2) if lat else None,
        "latency_p99_ms": round(percentile(lat, 0.99), 2) if lat else None,
    }


_RECEIVER = """
import selectors, socket, sys
port, n = int(sys.argv[1]), int(sys.argv[2])
socks = [socket.create_connection(("127.0.0.1", port)) for _ in range(n)]
sel = selectors.DefaultSelector()
for s in socks:
    s.setblocking(False)
    sel.register(s, selectors.EVENT_READ)
open_ = n
while open_:
    for key, _ in sel.select():
        try:
            data = key.fileobj.recv(1 << 16)
        except BlockingIOError:
            continue
        if not data:
            sel.unregister(key.fileobj)
            open_ -= 1
"""
"""The write floor's readers: ``n`` connections read (and dropped) in one process."""


def write_floor(n: int, size: int, rounds: int, rate_hz: float) -> float:
    """CPU microseconds one thread spends per ``send`` of ``size`` bytes to each of ``n``
    loopback TCP connections (read by another process), ``rounds`` times at ``rate_hz``: what
    the kernel and a bare Python loop cost per delivered message, the floor of any server's
    fan-out on this machine (a ceiling figure, as the ROS ceiling of the image scenario)."""
    import subprocess
    import sys

    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen(n)
        reader = subprocess.Popen([sys.executable, "-c", _RECEIVER,
                                   str(listener.getsockname()[1]), str(n)])
        conns = [listener.accept()[0] for _ in range(n)]
    try:
        for c in conns:
            c.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)  # as asyncio and uvloop do
        payload = b"x" * size
        cpu0 = time.thread_time()
        for _ in range(rounds):
            for c in conns:
                c.send(payload)
            time.sleep(1.0 / rate_hz)  # pacing as the publisher does, not synchronisation
        return 1e6 * (time.thread_time() - cpu0) / (rounds * n)
    finally:
        for c in conns:
            c.close()
        reader.wait(10)


SMALL: dict[str, Any] = {"kind": "stamp", "rate": 50.0, "subscribe": {"type": "std_msgs/msg/String",
                                                       "queue_length": 100}}
CAMERA: dict[str, Any] = {"kind": "image", "rate": 10.0, "subscribe": {"type": "sensor_msgs/msg/Image",
                                                        "compression": "cbor-raw",
                                                        "queue_length": 2}}


async def fanout(ctx: Ctx) -> dict[str, Any]:
    """The ``fanout`` scenario (see the module docstring)."""
    counts = (100, 200)
    seconds = 4.0 if ctx.quick else 10.0
    out: dict[str, Any] = {"bridge": [], "relay": []}
    out["write_floor_us"] = {
        str(n): round(await asyncio.to_thread(write_floor, n, 90, 100, 50.0), 2) for n in counts}
    bridge = await ctx.bridge().start()
    try:
        for n in counts:
            out["bridge"].append(await _step(ctx, bridge.url, bridge, n, topic=SMALL_TOPIC,
                                             seconds=seconds, **SMALL))
    finally:
        await bridge.stop()
    async with _tier(ctx) as (relays, robot):
        url = _url(relays[0])
        for n in counts:
            out["relay"].append(await _step(ctx, url, relays[0], n, topic=SMALL_TOPIC,
                                            seconds=seconds, robot=robot, **SMALL))
        out["camera_relay"] = await _step(ctx, url, relays[0], 100, topic=CAMERA_TOPIC,
                                          seconds=seconds, robot=robot, **CAMERA)
    return out
