"""How long ``ros.graph.params()`` takes (``--scenario params``).

A small graph: one rclpy node with parameters and one started without parameter services
(as another bridge's node is). ``cold`` is the first ``params()`` after both nodes and the
first one's parameter services are in the graph (the bridge has never asked that node),
``warm`` the median of the next calls; ``node`` is ``params(node)`` (names and values).
Targets (issue 42): warm under 50 ms, cold under 300 ms [2.03 s on every call before].
Nothing here asserts anything about time.
"""

from __future__ import annotations

import asyncio
import contextlib
import statistics
import sys
import time
from typing import Any

from bench.harness import Ctx, child_env

__all__ = ["params_scenario"]

_NODES = """
import rclpy
rclpy.init()
talker = rclpy.create_node("bench_params_talker")
for i in range(10):
    talker.declare_parameter(f"gain_{i}", float(i))
quiet = rclpy.create_node("bench_params_quiet", start_parameter_services=False)
executor = rclpy.executors.SingleThreadedExecutor()
executor.add_node(talker)
executor.add_node(quiet)
print("ready", flush=True)
try:
    executor.spin()
except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
    pass  # terminated: the benchmark is over
"""


async def params_scenario(ctx: Ctx) -> dict[str, Any]:
    """Cold and warm ``params()`` on a graph with a node lacking parameter services."""
    import roslibpy_lite

    bridge = await ctx.bridge().start()
    nodes = await asyncio.create_subprocess_exec(
        sys.executable, "-c", _NODES, env=child_env(ctx.domain),
        stdout=asyncio.subprocess.PIPE, stdin=asyncio.subprocess.DEVNULL)
    try:
        assert nodes.stdout is not None
        await asyncio.wait_for(nodes.stdout.readline(), 60)
        async with roslibpy_lite.connect(bridge.url) as ros:
            talker, quiet = "/bench_params_talker", "/bench_params_quiet"
            wanted = {f"{talker}/list_parameters", f"{talker}/get_parameters"}
            for _ in range(600):  # discovery has no event: ask until the graph shows both
                names = await ros.graph.node_names()
                if talker in names and quiet in names and wanted <= set(
                        (await ros.graph.node(talker)).services):
                    break
                await asyncio.sleep(0.05)
            start = time.perf_counter()
            found = await ros.graph.params()
            cold = time.perf_counter() - start
            warm = []
            for _ in range(5 if ctx.quick else 20):
                start = time.perf_counter()
                await ros.graph.params()
                warm.append(time.perf_counter() - start)
            start = time.perf_counter()
            values = await ros.graph.params(talker)
            node = time.perf_counter() - start
    finally:
        with contextlib.suppress(ProcessLookupError):
            nodes.terminate()
        await nodes.wait()
        await bridge.stop()
    return {
        "cold_ms": round(cold * 1000, 1),
        "warm_median_ms": round(statistics.median(warm) * 1000, 2),
        "node_values_ms": round(node * 1000, 1),
        "names": len(found),
        "node_values": len(values),
    }
