"""End-to-end benchmarks of the bridge, printed as JSON (one object per scenario, then a summary).

Run: ``python -m bench [--scenario all|NAME ...] [--duration S] [--quick] [--profile]``
(every option: ``python -m bench --help``). Nothing here asserts anything about time.

Each scenario starts its own bridge (``python -m bridge_server`` on
127.0.0.1, ephemeral port, a private ``ROS_DOMAIN_ID``); the ROS side of each
scenario runs in its own process (``bench/ros_side.py``), so the figures
measure the bridge. Clients are raw ``websockets`` connections (not our client
library), and they count frames without decoding big payloads.

Scenarios (targets; rosbridge_suite's figures in brackets):

- ``rclpy_ceiling``: one rclpy publisher process -> one rclpy subscriber process,
  no bridge: what the ROS side alone can carry (small strings, and the ``image``
  scenario's 640x480 images into a raw subscriber that deserialises nothing).
- ``ros_to_client``: highest rate of small std_msgs/String (step search, on a ladder to
  40,000 msg/s) where >= 99 % reach a websocket client. Target 8,000 msg/s [500].
- ``ros_to_client_raw``: the same with ``compression: cbor-raw`` (the client gets the CDR
  bytes as the bridge took them).
- ``client_to_ros``: the same from a websocket client to an rclpy subscriber.
  Target 10,000 msg/s [5,000].
- ``service``: call_service round trip to an rclpy SetBool service: p50 of
  sequential calls (target <= 1 ms) and calls/s with 16 in flight (target
  >= 1,000) [3.7 ms; 74 calls/s].
- ``client_service``: the mirror of ``service``: a websocket client serves SetBool, an rclpy
  client calls it through the bridge: p50/p99 of sequential calls, calls/s with 16 in flight.
- ``latency``: one-way ROS -> client latency at 200 Hz, p50/p99 (target p99 <= 1 ms) [1.6 ms].
- ``latency_side_by_side``: the same for our bridge and rosbridge_server_rs in one run,
  one publisher taking turns between their topics (and a plain rclpy subscriber's).
- ``image``: 640x480 rgb8 sensor_msgs/Image from an rclpy publisher as fast as it goes to
  one client; frames that reached the client in order per second of publishing, as JSON
  (target 60), CBOR (target 400) and cbor-raw [14; 360], beside the ROS ceiling (the same
  publisher into a raw rclpy subscriber, no bridge, measured the same way in the same run).
- ``idle_cpu``: the bridge's CPU with one connected client (target < 1 % of a core) [~5 %].
- ``memory_stall``: the bridge's RSS while one client stalls under an image
  flood: start, peak, end [rosbridge grew 400 MB in 6 s].
- ``pointcloud`` (``bench/cloud.py``): a 4 MiB PointCloud2 at 10 Hz to 5 clients, CBOR
  and cbor-raw: delivered per client, the bridge's CPU and RSS.
- ``relay_uplink`` (``bench/relay.py``): a 640x480 camera at 10 Hz to 1, 10, 50, 100
  viewers through a relay (the robot dials out over Zenoh) and straight to the bridge: the
  robot's uplink bytes against one viewer's, frames delivered, relay and robot CPU.
- ``relay_service`` (``bench/relay.py``): call_service round trips to an rclpy SetBool
  service through a relay and straight to the robot's bridge, in alternating blocks: p50/p99.
- ``relay_imu`` (``bench/relay.py``): a 100 Hz sensor_msgs/Imu to 200 JSON viewers (50 with
  ``--quick``) over two relays: the fraction delivered, latency p50/p99, the relays' CPU per
  message.
- ``fanout`` (``bench/fanout.py``): a 50 Hz topic to 100 and 200 JSON viewers of one
  bridge and of one relay, and a 10 Hz 640x480 camera to 100 cbor-raw viewers of one relay;
  the viewers run in processes of their own and count frames without decoding them:
  delivered, the server's CPU per delivered message (target <= 10 us), the write floor.
- ``relay_dead_link`` (``bench/relay.py``): a robot's Zenoh link blackholed (no FIN) while a
  viewer watches through the relay: seconds until the viewer's "went away" status, and until
  "is back" once restored, with ``--zenoh-lease 3`` (the default) and 10 (Zenoh's own).
- ``relay_outage`` (``bench/relay.py``): a robot's Zenoh link blackholed for 5, 15 and 60 s
  (5 and 15 with ``--quick``) while a reliable 10 Hz topic flows through a relay, with the
  default replay window (300 messages): messages lost, seconds from the restore to the last
  missed message delivered, the robot's RSS and window bytes during the outage.
- ``tls`` (``bench/tls.py``): small messages, service round trips and CBOR images over ws://
  and over wss://, side by side (reference only).
- ``workers_resume`` (``bench/workers.py``): with ``--workers 2``, call_service round trips
  through a resumed connection that its worker forwarded to the session's worker, against
  a direct one, over ws:// and wss://: p50/p99 of each (reference only).
- ``params`` (``bench/params.py``): ``ros.graph.params()`` on a graph with a node lacking
  parameter services: the first call and the median of the next (targets: warm < 50 ms,
  cold < 300 ms) [2.03 s on every call].
- ``links`` (``bench/links.py``): through ``bench/linkproxy.py``: a silent link (how soon
  each side notices), a 2 Mbit/s link (the age of the camera frames a client gets) and a
  resume across an 8 s outage (what each side got).
- ``record`` (``bench/bag.py``): ``roslibpy-lite bag record`` in its own process, a
  640x480 camera at 30 Hz plus an IMU at 200 Hz for 60 s: what the file holds against what
  was published, the recorder's CPU and write rate; then the camera alone at rising rates.
- ``foxglove`` (``bench/foxglove.py``): the Foxglove path against the rosbridge cbor-raw path
  on one bridge: 640x480 images at the publisher's pace and small messages per second to one
  client, and one 30 Hz camera to 10 viewers (the bridge's CPU per frame).
- ``action_ros_server`` / ``action_client_served`` (``bench/actions.py``): goal
  round trip p50/p99 and feedback throughput, to an rclpy action server and to a
  client-served action driven by an rclpy action client.
- ``fleet`` (``bench/fleet.py``): simulated robots (``bench/simrobot.py``: the bridge's own
  exporter over an in-memory graph), Zenoh routers in a mesh, relays behind HAProxy, many
  viewers: cost per unwatched robot, watched robot and viewer, open wait, delivery, flood
  isolation, recovery after a relay kill and a router restart, join/leave churn
  (``BENCH_FLEET_SIZES`` picks the sizes; docs/guides/sizing.md has the figures).

``--profile`` runs py-spy on the bridge during ``ros_to_client`` and
``image`` and adds the top functions (self and inclusive samples) to their results.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import platform
import re
import shutil
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from websockets.asyncio.client import ClientConnection

from bench.actions import action_client_served, action_ros_server
from bench.bag import record
from bench.cloud import pointcloud
from bench.compare import COMPARE_SCENARIOS, compare
from bench.fanout import fanout
from bench.fleet import fleet
from bench.foxglove import foxglove
from bench.harness import (
    CODE_ROOT,
    FRAME_SEQ_BYTES,
    IMAGE_GRACE,
    IMAGE_PUBLISHER,
    Bridge,
    Ctx,
    StalledClient,
    close_clients,
    frame_seq,
    percentile,
    send_op,
    ws_open,
)
from bench.links import links
from bench.params import params_scenario
from bench.relay import relay_dead_link, relay_imu, relay_outage, relay_service, relay_uplink
from bench.tls import tls_scenario
from bench.viewers import open_viewer
from bench.workers import workers_resume

TARGETS: dict[str, str] = {
    "rclpy_ceiling": "reference only",
    "ros_to_client": ">= 8,000 msg/s at >= 99 % (no less than 5,000) [rosbridge 500]",
    "ros_to_client_raw": "the same with compression cbor-raw: >= 40,000 msg/s at >= 99 %",
    "client_to_ros": ">= 10,000 msg/s at >= 99 % [rosbridge 5,000]",
    "service": "p50 <= 1 ms, >= 1,000 calls/s with 16 in flight [rosbridge 3.7 ms, 74/s]",
    "client_service": "p50 and p99 at or below rosbridge_server_rs's (--peer rs)",
    "latency": "p99 <= 1 ms at 200 Hz [rosbridge 1.6 ms]",
    "latency_side_by_side": "p50 and p99 at or below rosbridge_server_rs's, on one stream",
    "image": "JSON >= 60 frames/s, CBOR >= 400 frames/s [rosbridge 14; 360]",
    "idle_cpu": "< 1 % of a core [rosbridge ~5 %]",
    "memory_stall": "bounded [rosbridge +400 MB in 6 s]",
    "tls": "reference only: the cost of wss:// against ws://",
    "workers_resume": "reference: the forwarding hop of a resume on the wrong worker",
    "params": "graph.params() warm < 50 ms, cold < 300 ms, a node without parameter "
              "services in the graph [2.03 s every call]",
    "links": "reference: a silent link noticed in seconds; frame age flat over a 2 Mbit/s link",
    "pointcloud": "4 MiB PointCloud2 at 10 Hz to 5 clients: all delivered; bridge CPU, RSS",
    "foxglove": "the Foxglove path at least as fast as rosbridge cbor-raw on the same bridge; "
                "10 Foxglove viewers of one camera: bridge CPU per frame",
    "relay_uplink": "robot uplink through a relay flat in viewers (<= 1.1x one viewer's); "
                    "straight to the bridge N times",
    "relay_service": "reference: service round trip through a relay against straight",
    "fanout": "<= 10 us of server CPU per delivered message to 100-200 viewers, bridge and "
              "relay; 100 viewers of a 10 Hz camera through one relay get every frame",
    "relay_imu": "200 viewers of a 100 Hz IMU over two relays: all delivered; latency, relay CPU",
    "relay_dead_link": "a dead robot link told to its relay's clients within the lease (3 s)",
    "relay_outage": "nothing lost in a robot-link outage within the window (300 messages: "
                    "30 s at 10 Hz); what is past it counted; robot memory bounded",
    "record": "camera 30 Hz + IMU 200 Hz for 60 s recorded without a loss; recorder CPU",
    "action_ros_server": "reference: goal round trip p50/p99, feedback msg/s at >= 99 %",
    "action_client_served": "reference: goal round trip p50/p99, feedback msg/s at >= 99 %",
    "fleet": "unwatched robot < 50 KB on a relay, no CPU; open p99 < 200 ms; back < 10 s "
             "after a router restart; churn leaves relay RSS within 5 %",
}


class Profiler:
    """py-spy on the bridge for a while, reduced to the top functions."""

    def __init__(self, pid: int, seconds: float) -> None:
        self.pid = pid
        self.seconds = seconds
        self.out = Path(tempfile.mkdtemp(prefix="bench-pyspy-")) / "stacks.txt"
        self.proc: asyncio.subprocess.Process | None = None

    async def start(self) -> None:
        """Start sampling (nothing happens if py-spy is not installed)."""
        exe = shutil.which("py-spy")
        if exe is None:
            return
        self.proc = await asyncio.create_subprocess_exec(
            exe, "record", "--pid", str(self.pid), "--duration", str(max(1, round(self.seconds))),
            "--rate", "250", "--format", "raw", "--output", str(self.out), "--nonblocking",
            stdout=asyncio.subprocess.DEVNULL, stderr=asyncio.subprocess.DEVNULL,
        )

    async def result(self, top: int = 15) -> dict[str, Any]:
        """Wait for py-spy and summarise: top functions by self and by inclusive samples."""
        if self.proc is None:
            return {"error": "py-spy not installed"}
        try:
            await asyncio.wait_for(self.proc.wait(), self.seconds + 20)
        except TimeoutError:
            self.proc.kill()
            await self.proc.wait()
        if not self.out.exists():
            return {"error": "py-spy wrote nothing (permissions?)"}
        own: Counter[str] = Counter()
        incl: Counter[str] = Counter()
        total = 0
        for line in self.out.read_text().splitlines():
            stack, _, n = line.rpartition(" ")
            if not stack or not n.isdigit():
                continue
            count = int(n)
            total += count
            frames = [_short(f) for f in stack.split(";")]
            own[frames[-1]] += count
            for f in set(frames):
                incl[f] += count
        shutil.rmtree(self.out.parent, ignore_errors=True)

        def pct(c: Counter[str]) -> list[tuple[str, float]]:
            return [(f, round(100.0 * n / total, 1)) for f, n in c.most_common(top)] if total else []

        return {"samples": total, "self_pct": pct(own), "inclusive_pct": pct(incl)}


def cpu_seconds(pid: int) -> float:
    """User + system CPU seconds used so far by process ``pid`` (all its threads)."""
    import psutil

    t = psutil.Process(pid).cpu_times()
    return float(t.user + t.system)


def _short(frame: str) -> str:
    """``func (path/to/file.py:123)`` -> ``func (file.py:123)``."""
    name, sep, where = frame.partition(" (")
    if not sep:
        return frame
    return f"{name} ({os.path.basename(where.rstrip(')'))})"


# -- scenarios ---------------------------------------------------------------------------------


async def rclpy_ceiling(ctx: Ctx) -> dict[str, Any]:
    """One rclpy publisher process to one rclpy subscriber process, no bridge, as fast as possible."""
    topic = "/bench/ceiling"
    d = ctx.duration
    out: dict[str, Any] = {}
    for label, rate in (("max", 0.0), ("at_10k", 10_000.0)):
        sub = await ctx.ros("subscribe", "--topic", topic, "--duration", str(d + 20),
                            "--idle", "1.0").start()
        pub = await ctx.ros("publish", "--topic", topic, "--rate", str(rate), "--duration", str(d),
                            "--settle", "0.3").start()
        done = await pub.event("done", d + 40)
        got = await sub.event("done", 40)
        await pub.close()
        await sub.close()
        out[label] = {
            "published": done["sent"],
            "publish_rate": round(done["rate"]),
            "received": got["received"],
            "receive_rate": round(got["rate"]),
            "delivered_pct": round(100.0 * got["received"] / max(done["sent"], 1), 2),
        }
    out["image_640x480"] = await image_ceiling(ctx)
    return out


async def image_ceiling(ctx: Ctx) -> dict[str, Any]:
    """What rclpy alone delivers: :data:`IMAGE_PUBLISHER` to a raw rclpy subscriber (nothing
    deserialised; the history depth of 50 the bridge gives image subscriptions), no bridge."""
    topic = "/bench/ceiling_image"
    d = ctx.duration
    sub = await ctx.ros("subscribe", "--kind", "image", "--topic", topic, "--depth", "50",
                        "--duration", str(d + 20), "--idle", "1.0").start()
    pub = await ctx.ros("publish", "--topic", topic, *IMAGE_PUBLISHER, "--duration",
                        str(d)).start()
    try:
        done = await pub.event("done", d + 40)
        got = await sub.event("done", 40)
    finally:
        await pub.close()
        await sub.close()
    cutoff = done["t_end"] + IMAGE_GRACE
    in_order = sum(t <= cutoff for t in got["in_order_at"])
    return {"frames_per_s": round(in_order / done["elapsed"], 1), "in_order": in_order,
            "received": got["received"], "published": done["sent"],
            "publish_s": round(done["elapsed"], 2)}


SINK_PREFIX = 128
"""Bytes of a frame :class:`Sink` reads: the op's start and the String's number are in them."""
_JSON_SEQ = re.compile(rb'\{"op":"publish",.*?"msg":\{"data":"(\d+)')
# cbor-raw: the op's "bytes" key, its byte string's head, then the CDR of the String:
# encapsulation (4), the string's length (4), the decimal sequence number
_CDR_SEQ = re.compile(rb"\x65bytes(?:[\x40-\x57]|\x58.|\x59..)\x00\x01\x00\x00....(\d+)",
                      re.DOTALL)


class Sink:
    """Counts numbered std_msgs/String publish frames of one step from their first
    :data:`SINK_PREFIX` bytes (a counting viewer's, :mod:`bench.viewers`): the harness reads
    40,000 messages a second without decoding them."""

    def __init__(self, size: int) -> None:
        self.seen = bytearray(size)
        self.unique = 0
        self.frames = 0
        self.t_last = time.monotonic()

    def feed(self, prefix: bytes, _size: int = 0) -> None:
        """Count one frame from its first bytes (JSON text, or a cbor-raw binary frame: the
        CDR of a String); a frame that is not a numbered publish op counts as none."""
        m = _JSON_SEQ.match(prefix) if prefix[:1] == b"{" else _CDR_SEQ.search(prefix)
        if m is None:
            return
        self.frames += 1
        self.t_last = time.monotonic()
        seq = int(m.group(1))
        if 0 <= seq < len(self.seen) and not self.seen[seq]:
            self.seen[seq] = 1
            self.unique += 1


async def _drain_until(
    sink: Any, want: int, idle: float = 1.0, limit: float = 15.0
) -> None:
    """Wait until ``sink.unique`` reaches ``want`` or nothing arrived for ``idle`` seconds
    (counted from the later of the last arrival and this call), ``limit`` seconds at most."""
    start = time.monotonic()
    deadline = start + limit
    while sink.unique < want and time.monotonic() < deadline:
        if time.monotonic() - max(sink.t_last, start) > idle:
            return
        await asyncio.sleep(0.02)


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
            cpu0 = cpu_seconds(bridge.pid)
            pub = await ctx.ros("publish", "--topic", topic, "--rate", str(rate), "--duration",
                                str(d), "--settle", "0.3", "--linger", "3").start()
            await pub.event("matched")
            prof = None
            if ctx.profile and rate >= 4000:  # keep the profile of the last step run
                prof = Profiler(bridge.pid, d)
                await prof.start()
            done = await pub.event("done", d + 30)
            await _drain_until(sink, done["sent"])
            cpu = cpu_seconds(bridge.pid) - cpu0
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
            cpu0 = cpu_seconds(bridge.pid)
            t0 = loop.time()
            for i in range(n):
                due = t0 + i / rate
                ahead = due - loop.time()
                if ahead > 0.001:
                    await asyncio.sleep(ahead)
                await ws.send(f'{{"op":"publish","topic":"{topic}","msg":{{"data":"{i}"}}}}')
            sent_rate = n / (loop.time() - t0)
            got = await sub.event("done", d + 40)
            cpu = cpu_seconds(bridge.pid) - cpu0
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


async def service(ctx: Ctx) -> dict[str, Any]:
    """call_service round trips to an rclpy SetBool service: sequential latency, 16 in flight."""
    name = "/bench/srv"
    bridge = await ctx.bridge().start()
    srv = await ctx.ros("serve", "--service", name, "--duration", "300").start()
    await srv.event("ready")
    ws = await ws_open(bridge.url)
    waiting: dict[str, asyncio.Future[dict[str, Any]]] = {}

    async def reader() -> None:
        with contextlib.suppress(Exception):
            async for frame in ws:
                op = json.loads(frame)
                fut = waiting.pop(str(op.get("id")), None)
                if fut is not None and not fut.done():
                    fut.set_result(op)

    rtask = asyncio.create_task(reader())
    loop = asyncio.get_running_loop()
    counter = iter(range(10**9))

    errors: Counter[str] = Counter()

    async def call() -> dict[str, Any]:
        rid = f"c{next(counter)}"
        fut: asyncio.Future[dict[str, Any]] = loop.create_future()
        waiting[rid] = fut
        await send_op(ws, {"op": "call_service", "service": name, "type": "std_srvs/srv/SetBool",
                           "args": {"data": True}, "id": rid})
        reply = await fut
        if reply.get("result") is not True:
            errors[str(reply.get("values"))[:120]] += 1
        return reply

    try:
        deadline = time.monotonic() + 20
        while True:  # the first call waits for discovery
            reply = await asyncio.wait_for(call(), 25)
            if reply.get("result") is True:
                break
            if time.monotonic() > deadline:
                raise RuntimeError(f"service never answered: {reply}")
        for _ in range(50):
            await call()
        n_seq = 300 if ctx.quick else 1000
        lat: list[float] = []
        failures = 0
        for _ in range(n_seq):
            t = time.perf_counter_ns()
            reply = await call()
            lat.append((time.perf_counter_ns() - t) / 1e6)
            failures += reply.get("result") is not True
        in_flight = 16
        done = 0
        stop = time.monotonic() + ctx.duration
        t0 = time.monotonic()

        async def worker() -> None:
            nonlocal done, failures
            while time.monotonic() < stop:
                reply = await call()
                done += 1
                failures += reply.get("result") is not True

        await asyncio.gather(*(worker() for _ in range(in_flight)))
        elapsed = time.monotonic() - t0
    finally:
        await ws.close()
        rtask.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await rtask
        await srv.close()
        await bridge.stop()
    return {
        "sequential_calls": n_seq,
        "p50_ms": round(percentile(lat, 0.5), 3),
        "p90_ms": round(percentile(lat, 0.9), 3),
        "p99_ms": round(percentile(lat, 0.99), 3),
        "in_flight": in_flight,
        "calls_per_s": round(done / elapsed),
        "failures": failures,
        "failure_reasons": dict(errors),
    }


async def client_service(ctx: Ctx) -> dict[str, Any]:
    """An rclpy client calls a SetBool service a websocket client serves through the bridge:
    round trips of sequential calls (ROS request -> bridge -> client -> bridge -> ROS reply)
    and calls/s with 16 in flight; runs with ``--peer rs`` too."""
    import psutil

    name = "/bench/client_srv"
    bridge = await ctx.bridge().start()
    ws = await ws_open(bridge.url)
    await send_op(ws, {"op": "advertise_service", "service": name,
                       "type": "std_srvs/srv/SetBool"})
    served = [0]

    async def serve() -> None:
        with contextlib.suppress(Exception):
            async for frame in ws:
                op = json.loads(frame)
                if op.get("op") != "call_service":
                    continue
                served[0] += 1
                await send_op(ws, {"op": "service_response", "service": name,
                                   "id": op.get("id"), "result": True,
                                   "values": {"success": bool(op["args"]["data"]),
                                              "message": "ok"}})

    stask = asyncio.create_task(serve())
    proc = psutil.Process(bridge.pid)
    try:
        caller = await ctx.ros("call", "--service", name, "--calls",
                               str(300 if ctx.quick else 1000), "--in-flight", "16",
                               "--duration", str(ctx.duration), "--match-timeout", "20").start()
        await caller.event("matched", 30)
        cpu0, served0 = proc.cpu_times(), served[0]
        done = await caller.event("done", 120 + ctx.duration)
        cpu1, calls = proc.cpu_times(), served[0] - served0
        await caller.close()
    finally:
        await close_clients([ws], [stask])
        await bridge.stop()
    q = done["latency_ms"] or {}
    busy = cpu1.user - cpu0.user + cpu1.system - cpu0.system
    return {"sequential_calls": done["calls"], "p50_ms": q.get("p50"), "p90_ms": q.get("p90"),
            "p99_ms": q.get("p99"), "in_flight": done["in_flight"],
            "calls_per_s": round(done["calls_per_s"]), "failures": done["failed"],
            "unanswered": done["unanswered"], "served_by_client": served[0],
            "bridge_cpu_us_per_call": round(1e6 * busy / calls, 1) if calls else None}


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


class InOrder:
    """Counts the frames of a numbered stream and those that came in order (numbered above
    every frame before them: a late or repeated frame is not); frames without a number
    (a status op) are counted apart, as ``other``."""

    def __init__(self) -> None:
        self.frames = 0
        self.other = 0
        self.last = -1
        self.t_last = time.monotonic()
        self.in_order_at: list[float] = []
        """When each frame in order came (``time.monotonic()``)."""

    @property
    def unique(self) -> int:
        """Frames in order so far (what :func:`_drain_until` waits on)."""
        return len(self.in_order_at)

    def in_order_by(self, t: float) -> int:
        """Frames in order that came by ``t`` (``time.monotonic()``)."""
        return sum(at <= t for at in self.in_order_at)

    def feed(self, seq: int | None) -> None:
        """Count one frame numbered ``seq`` (``None``: not a frame of the stream)."""
        if seq is None:
            self.other += 1
            return
        self.frames += 1
        self.t_last = time.monotonic()
        if seq > self.last:
            self.in_order_at.append(self.t_last)
            self.last = seq


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
            cpu0 = cpu_seconds(bridge.pid)
            prof = None
            if ctx.profile:
                prof = Profiler(bridge.pid, ctx.duration)
                await prof.start()
            done = await pub.event("done", ctx.duration + 30)
            cutoff = done["t_end"] + IMAGE_GRACE
            await _drain_until(stream, done["sent"], idle=IMAGE_GRACE,
                               limit=cutoff - time.monotonic())
            cpu = cpu_seconds(bridge.pid) - cpu0
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


SCENARIOS: dict[str, Callable[[Ctx], Awaitable[dict[str, Any]]]] = {
    "rclpy_ceiling": rclpy_ceiling,
    "idle_cpu": idle_cpu,
    "ros_to_client": ros_to_client,
    "ros_to_client_raw": lambda ctx: ros_to_client(ctx, "cbor-raw"),
    "client_to_ros": client_to_ros,
    "service": service,
    "client_service": client_service,
    "latency": latency,
    "latency_side_by_side": latency_side_by_side,
    "image": image,
    "memory_stall": memory_stall,
    "tls": lambda ctx: tls_scenario(ctx, ros_to_client, service, image),
    "workers_resume": workers_resume,
    "params": params_scenario,
    "links": links,
    "record": record,
    "pointcloud": pointcloud,
    "foxglove": foxglove,
    "relay_uplink": relay_uplink,
    "relay_service": relay_service,
    "relay_imu": relay_imu,
    "fanout": fanout,
    "relay_dead_link": relay_dead_link,
    "relay_outage": relay_outage,
    "action_ros_server": action_ros_server,
    "action_client_served": action_client_served,
    "fleet": fleet,
}


def _headline(name: str, r: dict[str, Any]) -> Any:
    if "error" in r:
        return "error"
    if name == "rclpy_ceiling":
        return {"publish_rate": r["max"]["publish_rate"], "receive_rate": r["max"]["receive_rate"],
                "image_fps": r["image_640x480"]["frames_per_s"]}
    if name in ("ros_to_client", "ros_to_client_raw", "client_to_ros"):
        return r["best_rate_99pct"]
    if name in ("service", "client_service"):
        return {"p50_ms": r["p50_ms"], "p99_ms": r["p99_ms"], "calls_per_s": r["calls_per_s"]}
    if name == "latency":
        return {"p50_ms": r["p50_ms"], "p99_ms": r["p99_ms"]}
    if name == "latency_side_by_side":
        return {k: {"p50_ms": v["p50_ms"], "p99_ms": v["p99_ms"]}
                for k, v in r.items() if isinstance(v, dict) and "p50_ms" in v}
    if name == "image":
        return {k: r[k]["frames_per_s"] for k in ("json", "cbor", "cbor-raw") if k in r} | {
            "ros_ceiling": r["ros_ceiling"]["frames_per_s"]}
    if name == "idle_cpu":
        return r["connected_pct_of_core"]
    if name == "memory_stall":
        return {k: r[k] for k in ("rss_start_mb", "rss_peak_mb", "rss_end_mb")}
    if name.startswith("action_"):
        return {"p50_ms": r["round_trip"]["p50_ms"], "p99_ms": r["round_trip"]["p99_ms"],
                "feedback_rate_99pct": r["feedback_best_rate_99pct"]}
    if name == "pointcloud":
        return {c: {"all_delivered": r[c]["all_delivered"], "cpu_pct": r[c]["bridge_cpu_pct"],
                    "rss_peak_mb": r[c]["bridge_rss_mb"]["peak"]} for c in ("cbor", "cbor-raw")}
    if name == "foxglove":
        return {part: {path: r[part][path][key] for path in ("foxglove", "cbor-raw")}
                for part, key in (("image", "frames_per_s"), ("small", "best_rate_99pct"),
                                  ("viewers", "bridge_cpu_ms_per_published_frame"))}
    if name == "relay_uplink":
        return {way: {r["viewers"]: r["x_one_viewer"] for r in r[way]} for way in ("relay", "direct")}
    if name == "relay_service":
        return r
    if name == "fanout":
        return {part: [(s["viewers"], s["delivered_fraction"], s["server_cpu_us_per_message"])
                       for s in (r[part] if isinstance(r[part], list) else [r[part]])]
                for part in ("bridge", "relay", "camera_relay")}
    if name == "relay_dead_link":
        return {k: v["noticed_max_s"] for k, v in r.items() if k.startswith("lease_")}
    if name == "relay_outage":
        return {f"{o['outage_s']:g}s": {"lost": o["lost"], "recover_s": o["recover_s"]}
                for o in r["outages"]}
    if name == "relay_imu":
        return {k: r[k] for k in ("delivered_fraction", "latency_p50_ms", "latency_p99_ms",
                                  "relay_cpu_us_per_message")}
    if name == "record":
        return {"recorded_pct": {t: v["recorded_pct"] for t, v in r["camera_imu"]["topics"].items()},
                "recorder_cpu_pct": r["camera_imu"]["recorder_cpu_pct"],
                "best_camera_rate_99pct": r["best_camera_rate_99pct"]}
    if name == "params":
        return {k: r[k] for k in ("cold_ms", "warm_median_ms")}
    if name == "workers_resume":
        return {scheme: {kind: r[scheme][kind]["p50_ms"] for kind in ("direct", "forwarded")}
                for scheme in ("ws", "wss")}
    if name == "tls":
        keys = ("ros_to_client_best_rate_99pct", "service_p50_ms", "image_cbor_frames_per_s")
        return {scheme: {k: r[scheme][k] for k in keys} for scheme in ("ws", "wss")}
    return None


def _code() -> dict[str, str]:
    """Whose client and bridge were measured: the checkout, and where the client came from."""
    import importlib.util

    spec = importlib.util.find_spec("roslibpy_lite")
    return {"root": str(CODE_ROOT), "python": sys.executable,
            "roslibpy_lite": str(spec.origin) if spec else "not found"}


async def run(names: list[str], ctx: Ctx) -> int:
    """Run the scenarios in order, printing one JSON object each and a summary."""
    summary: dict[str, Any] = {}
    failed = 0
    t_all = time.monotonic()
    for name in names:
        t0 = time.monotonic()
        try:
            result = await SCENARIOS[name](ctx)
        except Exception as exc:  # report and go on with the next scenario
            result = {"error": f"{type(exc).__name__}: {exc}"}
            failed += 1
        result = {"scenario": name, "target": TARGETS[name], **result,
                  "wall_s": round(time.monotonic() - t0, 1)}
        print(json.dumps(result), flush=True)
        summary[name] = _headline(name, result)
    print(json.dumps({
        "summary": summary,
        "duration_per_step_s": ctx.duration,
        "quick": ctx.quick,
        "wall_s": round(time.monotonic() - t_all, 1),
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version()},
        "code": _code(),
    }), flush=True)
    return 1 if failed else 0


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The command line."""
    p = argparse.ArgumentParser(prog="python -m bench",
                                description="End-to-end benchmarks of the bridge (JSON output).")
    p.add_argument("--scenario", nargs="+", default=["all"],
                   help=f"all (the default), or some of: {', '.join(SCENARIOS)}")
    p.add_argument("--duration", type=float, default=None,
                   help="seconds per measurement step (default 3, --quick 1.5)")
    p.add_argument("--quick", action="store_true", help="short steps, fewer rates (~2 minutes)")
    p.add_argument("--profile", action="store_true",
                   help="py-spy the bridge during ros_to_client and image")
    p.add_argument("--domain", type=int, default=int(os.environ.get("BENCH_ROS_DOMAIN_ID", "42")),
                   help="ROS_DOMAIN_ID for the bridge and ROS side (default $BENCH_ROS_DOMAIN_ID, else 42)")
    p.add_argument("--ros-executor", choices=("events", "single"), default="events",
                   help="rclpy executor of the ROS-side processes (default events: much faster)")
    p.add_argument("--bridge-root", default=None,
                   help="run the bridge from another checkout (A/B comparisons); default: this one")
    p.add_argument("--peer", choices=("ours", "rs"), default="ours",
                   help="the server under test: ours, or rosbridge_server_rs (Rust; "
                   "../shared/peers/rosbridge_server_rs.sh, no rosapi) for side-by-side figures "
                   "(default ours)")
    p.add_argument("--compare", metavar="REV", default=None,
                   help="A/B: this tree against git revision REV, alternating, one table "
                   "(bench/README.md); the scenarios default to the compare set")
    p.add_argument("--repeat", type=int, default=3,
                   help="--compare: rounds of each side (default 3)")
    p.add_argument("--compare-json", metavar="PATH", default=None,
                   help="--compare: where to write the table as JSON (default: the cache folder)")
    p.add_argument("--bridge-arg", action="append", default=[],
                   help="extra bridge command-line argument (repeatable), e.g. --bridge-arg=--event-loop=asyncio")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Entry point."""
    args = parse_args(argv)
    if args.compare and args.scenario == ["all"]:
        names = list(COMPARE_SCENARIOS)
    else:
        names = list(SCENARIOS) if "all" in args.scenario else args.scenario
    unknown = [n for n in names if n not in SCENARIOS]
    if unknown:
        print(f"unknown scenario(s): {', '.join(unknown)}; known: {', '.join(SCENARIOS)}",
              file=sys.stderr)
        return 2
    if args.compare:
        return compare(args, names)
    duration = args.duration if args.duration is not None else (1.5 if args.quick else 3.0)
    ctx = Ctx(duration=duration, quick=args.quick, domain=args.domain, profile=args.profile,
              ros_executor=args.ros_executor, bridge_args=list(args.bridge_arg),
              bridge_root=args.bridge_root, peer=args.peer)
    return asyncio.run(run(names, ctx))


if __name__ == "__main__":
    sys.exit(main())
