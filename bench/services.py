"""Service round trips through the bridge, both ways: to an rclpy server (``service``) and to
one a websocket client serves (``client_service``)."""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from collections import Counter
from typing import Any

from bench.harness import Ctx, close_clients, percentile, send_op, ws_open
from bench.profiler import Profiler


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
        prof = await Profiler.maybe(ctx.profile, bridge.pid, ctx.duration + 2)
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
        profile = await prof.result() if prof is not None else None
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
        **({"profile": profile} if profile is not None else {}),
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
        prof = await Profiler.maybe(ctx.profile, bridge.pid, 2 * ctx.duration)
        done = await caller.event("done", 120 + ctx.duration)
        cpu1, calls = proc.cpu_times(), served[0] - served0
        await caller.close()
        profile = await prof.result() if prof is not None else None
    finally:
        await close_clients([ws], [stask])
        await bridge.stop()
    q = done["latency_ms"] or {}
    busy = cpu1.user - cpu0.user + cpu1.system - cpu0.system
    return {"sequential_calls": done["calls"], "p50_ms": q.get("p50"), "p90_ms": q.get("p90"),
            "p99_ms": q.get("p99"), "in_flight": done["in_flight"],
            "calls_per_s": round(done["calls_per_s"]), "failures": done["failed"],
            "unanswered": done["unanswered"], "served_by_client": served[0],
            "bridge_cpu_us_per_call": round(1e6 * busy / calls, 1) if calls else None,
            **({"profile": profile} if profile is not None else {})}
