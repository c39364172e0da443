"""``python -m bench.mcp``: what the MCP server adds over our client's own calls.

Starts a bridge (127.0.0.1, its own ROS domain), a service and a topic served by a
roslibpy-lite client through it, and ``roslibpy-lite mcp`` as a child process driven over
stdio by the mcp SDK's own client. Prints JSON:

- ``service``: p50/p99 ms of ``call__<service>`` through MCP and of ``ros.call_service``
  direct, and their difference (the overhead);
- ``topic_read``: the same for ``read_topic`` and the client's own subscribe, first
  message, unsubscribe on a topic published at 200 Hz;
- ``list_tools``: ms to list the tools of a graph of ``--topics`` topics and ``--services``
  services (the first listing, which loads types and asks the bridge's may_*, and the
  following ones).

Nothing here asserts anything about time.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import sys
import time
from collections.abc import Awaitable, Callable
from typing import Any

from mcp import Client, StdioServerParameters

import roslibpy_lite
from bench.harness import CODE_ROOT, Bridge, child_env, percentile


def _quantiles(samples: list[float]) -> dict[str, float]:
    return {"p50_ms": round(percentile(samples, 0.5) * 1e3, 3),
            "p99_ms": round(percentile(samples, 0.99) * 1e3, 3)}


async def _timed(n: int, call: Callable[[], Awaitable[Any]]) -> list[float]:
    for _ in range(min(n, 20)):  # warm-up
        await call()
    samples = []
    for _ in range(n):
        t0 = time.perf_counter()
        await call()
        samples.append(time.perf_counter() - t0)
    return samples


def _compare(mcp: list[float], direct: list[float]) -> dict[str, Any]:
    a, b = _quantiles(mcp), _quantiles(direct)
    return {"mcp": a, "client": b,
            "overhead_p50_ms": round(a["p50_ms"] - b["p50_ms"], 3),
            "overhead_p99_ms": round(a["p99_ms"] - b["p99_ms"], 3)}


async def run(args: argparse.Namespace) -> dict[str, Any]:
    """Start everything, measure, stop; the figures as a dict."""
    bridge = await Bridge(args.domain).start()
    out: dict[str, Any] = {}
    try:
        async with roslibpy_lite.connect(bridge.url) as ros:
            await ros.advertise_service("/bench/scale", "mult_msgs/srv/MultFloats",
                                        lambda req: {"result": req["x"] * req["y"]})
            pub = await ros.advertise("/bench/chatter", "std_msgs/msg/String")

            async def publish() -> None:
                while True:
                    await pub.publish({"data": "x" * 64})
                    await asyncio.sleep(0.005)

            ticker = asyncio.create_task(publish())
            params = StdioServerParameters(
                command=sys.executable, args=["-m", "roslibpy_lite.cli", "mcp", "--url",
                                              bridge.url],
                cwd=CODE_ROOT, env=child_env(args.domain))
            async with Client(params, read_timeout_seconds=60) as client:
                names = {t.name for t in (await client.list_tools()).tools}
                assert "call__bench__scale" in names, names
                request = {"x": 2.0, "y": 3.0}
                out["service"] = _compare(
                    await _timed(args.n, lambda: client.call_tool(
                        "call__bench__scale", {"request": request})),
                    await _timed(args.n, lambda: ros.call_service(
                        "/bench/scale", "mult_msgs/srv/MultFloats", request)))

                async def direct_read() -> None:
                    async with ros.subscribe("/bench/chatter", "std_msgs/msg/String",
                                             buffer_size=1) as sub:
                        await sub.get()

                out["topic_read"] = _compare(
                    await _timed(args.n, lambda: client.call_tool(
                        "read_topic", {"topic": "/bench/chatter"})),
                    await _timed(args.n, direct_read))
            ticker.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await ticker
            out["list_tools"] = await _list_tools(ros, bridge, args)
    finally:
        await bridge.stop()
    return out


async def _list_tools(ros: Any, bridge: Bridge, args: argparse.Namespace) -> dict[str, Any]:
    types = ["std_msgs/msg/String", "geometry_msgs/msg/Twist", "sensor_msgs/msg/Imu",
             "sensor_msgs/msg/Image"]
    for i in range(args.topics):
        await ros.advertise(f"/bench/t{i}", types[i % len(types)])
    for i in range(args.services):
        await ros.advertise_service(f"/bench/s{i}", "std_srvs/srv/SetBool",
                                    lambda req: {"success": True, "message": ""})
    params = StdioServerParameters(
        command=sys.executable, args=["-m", "roslibpy_lite.cli", "mcp", "--url", bridge.url],
        cwd=CODE_ROOT, env=child_env(args.domain))
    async with Client(params, read_timeout_seconds=120) as client:
        t0 = time.perf_counter()
        first = await client.list_tools(cache_mode="refresh")
        cold = time.perf_counter() - t0
        warm = await _timed(5, lambda: client.list_tools(cache_mode="refresh"))
    return {"topics": args.topics, "services": args.services, "tools": len(first.tools),
            "first_ms": round(cold * 1e3, 1), "then_p50_ms": round(percentile(warm, 0.5) * 1e3, 1)}


def main() -> None:
    """Parse the options, run, print the JSON."""
    parser = argparse.ArgumentParser(prog="python -m bench.mcp", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("-n", type=int, default=300, help="calls per figure (default 300)")
    parser.add_argument("--topics", type=int, default=200,
                        help="topics of the list_tools graph (default 200)")
    parser.add_argument("--services", type=int, default=100,
                        help="services of the list_tools graph (default 100)")
    parser.add_argument("--domain", type=int,
                        default=int(os.environ.get("BENCH_ROS_DOMAIN_ID", "77")),
                        help="the ROS domain (default $BENCH_ROS_DOMAIN_ID or 77)")
    print(json.dumps(asyncio.run(run(parser.parse_args())), indent=2))


if __name__ == "__main__":
    main()
