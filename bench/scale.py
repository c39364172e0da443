"""The scale benchmark: many clients on one 50 Hz topic, and many idle connections.

Run: ``python -m bench.scale [--workers 1 2] [--clients 50 100 200] [--idle 1000]
[--duration 5] [--domain 42]``. Prints one JSON object per bridge configuration.

For each ``--workers`` value one bridge is started (``--workers W``). Then, for
each client count N (cumulative: clients are added, never replaced), every
client subscribes to a fresh topic, an rclpy process publishes stamped
``std_msgs/String`` at ``--rate`` Hz (default 50) for ``--duration`` seconds,
and the step reports:

- ``delivered_pct``: messages received by all clients / (sent x N);
- ``latency_ms``: p50 / p99 / max, ROS publish -> client receive (monotonic
  clock, same machine);
- ``bridge_cpu_pct``: CPU of every bridge process (supervisor and workers)
  over the step, in % of one core; ``bridge_rss_mb``: their summed RSS;
- ``per_worker_clients``: how the kernel spread the connections.

Then ``--idle`` connections are opened (no subscription): the bridge's RSS
before and after gives the memory per connection, and its CPU while they sit
idle is measured too. Clients run in this process (one asyncio loop), so at
high totals the client side's own CPU limits what it can take in: look at the
bench process's ``client_cpu_pct`` next to the bridge's figures.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import resource
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import psutil
from websockets.asyncio.client import ClientConnection, connect

from bench.harness import Bridge, RosSide, percentile

MB = 1024 * 1024


class Tree:
    """CPU and RSS of the bridge process and its children (the workers)."""

    def __init__(self, pid: int) -> None:
        self.root = psutil.Process(pid)

    def procs(self) -> list[psutil.Process]:
        """The supervisor (or the single bridge) and its workers."""
        return [self.root, *self.root.children(recursive=True)]

    def cpu(self) -> float:
        """CPU seconds used so far by all of them."""
        total = 0.0
        for p in self.procs():
            with contextlib.suppress(psutil.Error):
                t = p.cpu_times()
                total += t.user + t.system
        return total

    def rss(self) -> int:
        """Summed resident memory in bytes."""
        total = 0
        for p in self.procs():
            with contextlib.suppress(psutil.Error):
                total += p.memory_info().rss
        return total


class Client:
    """One websocket client counting stamped messages of the current topic."""

    def __init__(self, ws: ClientConnection) -> None:
        self.ws = ws
        self.worker = ws.response.headers.get("X-Bridge-Worker", "0") if ws.response else "0"
        self.topic = ""
        self.received = 0
        self.latencies: list[float] = []
        self.replies: asyncio.Queue[str] = asyncio.Queue()
        self.task = asyncio.create_task(self._read())

    async def _read(self) -> None:
        with contextlib.suppress(Exception):
            async for frame in self.ws:
                now = time.monotonic_ns()
                op = json.loads(frame)
                if op.get("op") == "publish" and op.get("topic") == self.topic:
                    seq, stamp = op["msg"]["data"].split(" ")
                    self.received += 1
                    if int(seq) >= 10:  # skip the start-up
                        self.latencies.append((now - int(stamp)) / 1e6)
                elif op.get("op") == "service_response":
                    self.replies.put_nowait(str(op.get("id")))

    async def follow(self, topic: str) -> None:
        """Subscribe to ``topic`` (leaving the previous one) and wait until the bridge has it."""
        if self.topic:
            await self.ws.send(json.dumps({"op": "unsubscribe", "topic": self.topic}))
        self.topic, self.received, self.latencies = topic, 0, []
        await self.ws.send(json.dumps({"op": "subscribe", "topic": topic,
                                       "type": "std_msgs/msg/String"}))
        await self.ws.send(json.dumps({"op": "call_service", "id": "sync",
                                       "service": "/rosapi/get_ros_version"}))
        await asyncio.wait_for(self.replies.get(), 30)

    async def close(self) -> None:
        """Close the connection."""
        with contextlib.suppress(Exception):
            await self.ws.close()
        self.task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await self.task


async def _open(url: str) -> ClientConnection:
    return await connect(url, max_size=None, compression=None, open_timeout=30,
                         ping_interval=None)


async def _open_many(url: str, n: int, batch: int = 50) -> list[ClientConnection]:
    out: list[ClientConnection] = []
    while len(out) < n:
        k = min(batch, n - len(out))
        out += await asyncio.gather(*(_open(url) for _ in range(k)))
    return out


async def run_config(args: argparse.Namespace, workers: int) -> dict[str, Any]:
    """One bridge with ``workers`` workers: the client steps, then the idle connections."""
    bridge_args = ["--workers", str(workers), "--max-clients", "0"]
    bridge = await Bridge(args.domain, bridge_args).start(timeout=60)
    tree = Tree(bridge.pid)
    me = psutil.Process()
    clients: list[Client] = []
    steps: list[dict[str, Any]] = []
    out: dict[str, Any] = {"workers": workers, "rate_hz": args.rate, "steps": steps}
    try:
        for n in args.clients:
            clients += [Client(ws) for ws in await _open_many(bridge.url, n - len(clients))]
            topic = f"/bench/scale_{workers}_{n}"
            await asyncio.gather(*(c.follow(topic) for c in clients))
            pub = await RosSide(args.domain, "publish", "--topic", topic, "--kind", "stamp",
                                "--rate", str(args.rate), "--duration", str(args.duration),
                                "--wait-subs", str(workers), "--settle", "0.5",
                                "--linger", "1.5").start()
            await pub.event("matched", 60)
            cpu0, mine0, t0 = tree.cpu(), me.cpu_times(), time.monotonic()
            done = await pub.event("done", args.duration + 60)
            wall = time.monotonic() - t0
            cpu, mine = tree.cpu() - cpu0, me.cpu_times()
            rss = tree.rss()
            want = done["sent"]
            deadline = time.monotonic() + 5
            while time.monotonic() < deadline and any(c.received < want for c in clients):
                await asyncio.sleep(0.05)
            await pub.close()
            lat = [x for c in clients for x in c.latencies]
            spread: dict[str, int] = {}
            by_worker: dict[str, list[float]] = {}
            for c in clients:
                spread[c.worker] = spread.get(c.worker, 0) + 1
                by_worker.setdefault(c.worker, []).extend(c.latencies)
            steps.append({
                "clients": n,
                "sent_per_client": want,
                "delivered_pct": round(100.0 * sum(c.received for c in clients) / (want * n), 2),
                "clients_missing_any": sum(c.received < want for c in clients),
                "latency_ms": {"p50": round(percentile(lat, 0.5), 2),
                               "p99": round(percentile(lat, 0.99), 2),
                               "max": round(max(lat), 2) if lat else None},
                "bridge_cpu_pct": round(100.0 * cpu / wall, 1),
                "bridge_rss_mb": round(rss / MB, 1),
                "client_cpu_pct": round(100.0 * ((mine.user + mine.system)
                                                 - (mine0.user + mine0.system)) / wall, 1),
                "msgs_out_per_s": round(want * n / args.duration),
                "per_worker_clients": dict(sorted(spread.items())),
                "per_worker_p99_ms": {w: round(percentile(v, 0.99), 2)
                                      for w, v in sorted(by_worker.items())},
            })
            print(json.dumps({"workers": workers, **steps[-1]}), file=sys.stderr, flush=True)
        for c in clients:
            await c.close()
        clients = []
        if args.idle:
            await asyncio.sleep(1.0)  # let the bridge release the closed sessions
            rss0 = tree.rss()
            idle = await _open_many(bridge.url, args.idle)
            await asyncio.sleep(1.0)
            rss1 = tree.rss()
            cpu0, t0 = tree.cpu(), time.monotonic()
            await asyncio.sleep(3.0)
            idle_cpu = 100.0 * (tree.cpu() - cpu0) / (time.monotonic() - t0)
            out["idle"] = {
                "connections": len(idle),
                "rss_before_mb": round(rss0 / MB, 1),
                "rss_after_mb": round(rss1 / MB, 1),
                "kb_per_connection": round((rss1 - rss0) / 1024 / len(idle), 1),
                "bridge_cpu_pct_idle": round(idle_cpu, 2),
            }
            await asyncio.gather(*(ws.close() for ws in idle), return_exceptions=True)
    finally:
        for c in clients:
            await c.close()
        await bridge.stop()
    return out


async def main_async(args: argparse.Namespace) -> int:
    """Every configuration in turn."""
    for workers in args.workers:
        t0 = time.monotonic()
        try:
            result = await run_config(args, workers)
        except Exception as exc:
            result = {"workers": workers, "error": f"{type(exc).__name__}: {exc}"}
        result["wall_s"] = round(time.monotonic() - t0, 1)
        print(json.dumps(result), flush=True)
    return 0


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The command line."""
    p = argparse.ArgumentParser(description="Scale benchmark of the bridge (JSON output).")
    p.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    p.add_argument("--clients", type=int, nargs="+", default=[50, 100, 200],
                   help="client counts, ascending (default 50 100 200)")
    p.add_argument("--idle", type=int, default=1000, help="idle connections (0: skip)")
    p.add_argument("--rate", type=float, default=50.0, help="topic rate in Hz (default 50)")
    p.add_argument("--duration", type=float, default=5.0, help="seconds per step (default 5)")
    p.add_argument("--domain", type=int, default=int(os.environ.get("BENCH_ROS_DOMAIN_ID", "42")))
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Entry point."""
    args = parse_args(argv)
    need = max(args.clients) + args.idle + 256
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft < need:  # the bridge (a child) inherits the raised limit too
        resource.setrlimit(resource.RLIMIT_NOFILE, (min(max(need, soft), hard), hard))
    return asyncio.run(main_async(args))


if __name__ == "__main__":
    sys.exit(main())
