"""Action benchmarks through the bridge (scenarios of ``bench/run.py``), both directions.

- ``action_ros_server``: a websocket client sends goals to an rclpy action server
  (``bench/ros_actions_side.py serve``): round trip of sequential goals
  (send_action_goal to action_result, p50/p99), then feedback throughput: the
  highest feedback rate of which >= 99 % reach the client.
- ``action_client_served``: a websocket client serves the action; an rclpy action
  client (``ros_actions_side.py call`` / ``feedback``) drives it: the same two figures.
  Feedback counts what reaches the rclpy client before the result: rclpy's action
  client takes one feedback per executor round and drops what is left once the
  result arrives, which limits this direction more than the bridge does.

For reference, ``action_ros_server`` also measures the round trip of an rclpy
action client to the same server without the bridge (``rclpy_only_round_trip``).

Nothing here asserts anything about time.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from typing import Any

from bench.harness import ROOT, Ctx, RosSide, percentile, ws_open

FIB = "test_msgs/action/Fibonacci"
ACTION_SIDE = str(ROOT / "bench" / "ros_actions_side.py")


class ActionSide(RosSide):
    """A ``bench/ros_actions_side.py`` process (events as for :class:`RosSide`)."""

    script = ACTION_SIDE


def _rates(ctx: Ctx) -> list[int]:
    if ctx.quick:
        return [1000, 2000, 4000, 6000]
    return [1000, 2000, 4000, 6000, 8000, 10000, 15000]


def _summary(lat: list[float], failed: int) -> dict[str, Any]:
    return {"goals": len(lat), "p50_ms": round(percentile(lat, 0.5), 3),
            "p99_ms": round(percentile(lat, 0.99), 3), "failed": failed}


async def action_ros_server(ctx: Ctx) -> dict[str, Any]:
    """Client -> rclpy action server: goal round trip and feedback throughput."""
    name = "/bench/action"
    d = ctx.duration
    bridge = await ctx.bridge().start()
    server = await ActionSide(ctx.domain, "serve", "--action", name, "--duration", str(d)).start()
    await server.event("ready")
    ws = await ws_open(bridge.url)
    results: dict[str, asyncio.Future[dict[str, Any]]] = {}
    feedback: dict[str, set[int]] = {}
    loop = asyncio.get_running_loop()

    async def reader() -> None:
        with contextlib.suppress(Exception):
            async for frame in ws:
                op = json.loads(frame)
                gid = str(op.get("id"))
                if op.get("op") == "action_feedback":
                    feedback.setdefault(gid, set()).update(op["values"]["sequence"])
                elif op.get("op") == "action_result" and gid in results:
                    results.pop(gid).set_result(op)

    rtask = asyncio.create_task(reader())
    counter = iter(range(10**9))

    async def goal(order: int, fb: bool = False, timeout: float = 30) -> dict[str, Any]:
        gid = f"g{next(counter)}"
        fut: asyncio.Future[dict[str, Any]] = loop.create_future()
        results[gid] = fut
        await ws.send(json.dumps({"op": "send_action_goal", "action": name, "action_type": FIB,
                                  "args": {"order": order}, "feedback": fb, "id": gid}))
        op = await asyncio.wait_for(fut, timeout)
        op["seen"] = len(feedback.pop(gid, ()))
        return op

    try:
        await goal(0)  # discovery
        for _ in range(20):
            await goal(0)
        lat: list[float] = []
        failed = 0
        for _ in range(300 if ctx.quick else 1000):
            t = time.perf_counter_ns()
            op = await goal(0)
            lat.append((time.perf_counter_ns() - t) / 1e6)
            failed += op.get("result") is not True
        steps, best = [], 0
        for rate in _rates(ctx):
            op = await goal(rate, fb=True, timeout=d + 30)
            sent = op["values"]["sequence"][0]
            pct = 100.0 * op["seen"] / max(sent, 1)
            steps.append({"rate": rate, "sent": sent, "received": op["seen"],
                          "delivered_pct": round(pct, 2)})
            if pct < 99.0:
                break
            best = rate
        n = 300 if ctx.quick else 1000
        direct = await ActionSide(ctx.domain, "call", "--action", name, "--goals", str(n)).start()
        q = (await direct.event("done", 120))["latency_ms"] or {}
        await direct.close()
    finally:
        await ws.close()
        rtask.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await rtask
        await server.close()
        await bridge.stop()
    return {"round_trip": _summary(lat, failed), "feedback_best_rate_99pct": best,
            "feedback_steps": steps,
            "rclpy_only_round_trip": {"p50_ms": q.get("p50"), "p99_ms": q.get("p99")}}


async def action_client_served(ctx: Ctx) -> dict[str, Any]:
    """rclpy action client -> client-served action: goal round trip and feedback throughput."""
    name = "/bench/served_action"
    d = ctx.duration
    bridge = await ctx.bridge().start()
    ws = await ws_open(bridge.url)
    await ws.send(json.dumps({"op": "advertise_action", "action": name, "type": FIB}))
    streams: set[asyncio.Task[None]] = set()

    async def result(gid: str, count: int) -> None:
        await ws.send(json.dumps({"op": "action_result", "id": gid, "action": name,
                                  "values": {"sequence": [count]}, "status": 4, "result": True}))

    async def stream(gid: str, rate: int) -> None:
        n = int(rate * d)
        t0 = loop.time()
        for seq in range(n):
            ahead = t0 + seq / rate - loop.time()
            if ahead > 0.001:
                await asyncio.sleep(ahead)
            await ws.send(f'{{"op":"action_feedback","id":"{gid}","action":"{name}",'
                          f'"values":{{"sequence":[{seq}]}}}}')
        await result(gid, n)

    async def serve() -> None:
        with contextlib.suppress(Exception):
            async for frame in ws:
                op = json.loads(frame)
                if op.get("op") != "send_action_goal":
                    continue
                order = op["args"]["order"]
                if order == 0:
                    await result(op["id"], 0)
                else:
                    task = asyncio.create_task(stream(op["id"], order))
                    streams.add(task)
                    task.add_done_callback(streams.discard)

    loop = asyncio.get_running_loop()
    stask = asyncio.create_task(serve())
    try:
        n = 300 if ctx.quick else 1000
        caller = await ActionSide(ctx.domain, "call", "--action", name, "--goals", str(n)).start()
        done = await caller.event("done", 120)
        await caller.close()
        q = done["latency_ms"] or {}
        round_trip = {"goals": n, "p50_ms": q.get("p50"), "p99_ms": q.get("p99"),
                      "failed": done["failed"]}
        steps, best = [], 0
        for rate in _rates(ctx):
            fb = await ActionSide(ctx.domain, "feedback", "--action", name,
                                  "--rate", str(rate)).start()
            got = await fb.event("done", d + 60)
            await fb.close()
            pct = 100.0 * got["unique"] / max(got["sent"], 1)
            steps.append({"rate": rate, "sent": got["sent"], "received": got["unique"],
                          "delivered_pct": round(pct, 2), "result_s": got["result_s"],
                          "feedback_s": [got["first_feedback_s"], got["last_feedback_s"]]})
            if pct < 99.0:
                break
            best = rate
    finally:
        await ws.close()
        stask.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await stask
        await bridge.stop()
    return {"round_trip": round_trip, "feedback_best_rate_99pct": best, "feedback_steps": steps}
