"""A fleet through the relay tier (``--scenario fleet``): many simulated robots, Zenoh
routers in a mesh, relays behind HAProxy, many viewers; what each costs and how it recovers.

At each size (robots, routers, relays, viewers; :data:`~bench.fleettier.SIZES`,
:data:`~bench.fleettier.QUICK`, or
``BENCH_FLEET_SIZES="robots x routers x relays x viewers [x watched],..."``), its processes
started and stopped by :class:`~bench.fleettier.Tier`:

1. routers (``bench/zrouter.py``; the second and later dial the first: a mesh), relays
   (``python -m bridge_server.zenoh.relay``, Zenoh clients of the routers in turn) and
   HAProxy before the relays (:func:`bench.fleetproc.haproxy_config`);
2. the robots (``bench/simrobot.py``, :data:`~bench.fleettier.PER_PROCESS` a process; each
   dials one router):
   relay and router RSS and CPU before and with them, nobody watching: **per unwatched robot**;
3. up to :data:`OPEN_ONE` idle robots opened one after another by one viewer: **opening
   one robot** (p50, p99), nothing else opening meanwhile (:func:`open_one_by_one`); then
   one probe viewer per watched robot (``/pose``; the watched robots spread over the robot
   processes, :meth:`~bench.fleettier.Size.watched_names`), through the balancer: **per
   watched robot**, and how long opening a robot takes (the handshake: the relay opens the
   robot), then the viewers (``bench/fleetview.py``; each 1-3 robots, 90 % ``/status`` at
   1 Hz, 10 % ``/pose`` at 10 Hz, one in 500 (at most 3) a camera): **per viewer**, and
   their open and first-message times;
4. a window: **delivered fraction and p99 latency** per robot; then one robot floods
   (100 KB messages at 100 Hz to two viewers) and the same window again: the others'
   fraction and p99 beside their own without the flood;
5. a relay killed (SIGKILL): seconds until each viewer hears its robot again (through the
   balancer, subscriptions restored); a router killed and restarted on its port: seconds
   from the restart until each robot holds its name again and each viewer hears it;
6. robots joining and leaving, one a second, each opened by a viewer: relay RSS and the
   robots it still lists before and after; then the same again (``churn_again``): the
   first round raises the relays' RSS to what the robots open at once need (Python and
   the C allocator keep freed memory for reuse), and a second shows whether robots that
   left leave anything behind beyond that.

After the first window and at the end, the balancers' own counts (from HAProxy's
statistics page, :meth:`~bench.fleettier.Tier.balancer_counts`): connections taken, passed
to each relay, passed to none, and how often and how long their health checks held each
relay down; beside them, the clients the relays' logs counted (``relay_lines``).

With ``--profile``, py-spy on the first relay during step 4's first window and while its status
page is read, and on it and the first robot process for the first seconds after the router's
restart (their top functions in the result).

Robots, viewers, relays, routers and HAProxy share this machine's cores: at the larger
sizes the viewers' and robots' own CPU is part of what limits the figures (printed
beside them). Nothing here asserts anything about time.
"""

from __future__ import annotations

import asyncio
import contextlib
import http.client
import random
import tempfile
import time
from pathlib import Path
from typing import Any

from bench.fleetproc import Child, get
from bench.fleettier import Size, Tier, sizes
from bench.harness import Ctx, percentile
from bench.profiler import Profiler

__all__ = ["churn", "delivery", "fleet", "run_size", "window"]

OPEN_ONE = 20
"""Robots opened one at a time (:func:`open_one_by_one`) at each size."""
STATUS_PROFILE_S = 20.0
"""Seconds of py-spy on the first relay from the start of a read of its status page."""
CHURN_CONTROL_S = 60.0
"""Seconds, at most the churn's own, that the relays' RSS is watched without churn first."""
RESTART_PROFILE_S = 15.0
"""Seconds of py-spy after a router's restart (``--profile``)."""


def _q(values: list[float], scale: float = 1.0) -> dict[str, float | None]:
    if not values:
        return {"p50": None, "p99": None, "max": None}
    return {"p50": round(percentile(values, 0.5) * scale, 3),
            "p99": round(percentile(values, 0.99) * scale, 3), "max": round(max(values) * scale, 3)}


def delivery(stats: dict[str, Any], skip: frozenset[str] = frozenset()) -> dict[str, Any]:
    """Per robot (but ``skip``): fraction of numbered messages delivered, p99 latency (ms);
    their worst and median across robots; the robots none of whose viewers heard anything
    (``silent_robots``, the first of them by name); messages heard again (``repeated``) or
    unreadable (``malformed``, with the first as ``odd``), and the viewers' reconnections so
    far."""
    fractions, p99s = [], []
    silent: list[str] = []
    repeated = malformed = 0
    for robot, r in stats["robots"].items():
        malformed += r.get("malformed", 0) if robot not in skip else 0
        if robot not in skip and r["got"] + r["missed"] + r["frames"] == 0:
            silent.append(robot)
        if robot in skip or r["got"] + r["missed"] == 0:
            continue
        fractions.append(r["got"] / (r["got"] + r["missed"]))
        repeated += r["repeated"]
        if r["latency_ms"]:
            p99s.append(percentile(r["latency_ms"], 0.99))
    return {"robots": len(fractions),
            "delivered_min": round(min(fractions), 4) if fractions else None,
            "delivered_median": round(percentile(fractions, 0.5), 4) if fractions else None,
            "latency_p99_ms_median": round(percentile(p99s, 0.5), 1) if p99s else None,
            "latency_p99_ms_worst": round(max(p99s), 1) if p99s else None,
            "repeated": repeated, "malformed": malformed, "odd": stats.get("odd"),
            "silent_robots": len(silent), "silent_first": sorted(silent)[:5],
            "reconnects": stats.get("reconnects")}


def viewer_plan(watched: list[str], n: int, seed: int = 49) -> list[tuple[list[str], str]]:
    """``n`` viewers over the ``watched`` robots: each 1-3 of them; 90 % on ``/status``, 10 %
    on ``/pose``; a few (one per 500, at most 3) on the first robots' cameras, one each (a
    camera is 9 MB/s a viewer: more would measure this machine's loopback)."""
    rng = random.Random(seed)
    plan: list[tuple[list[str], str]] = []
    for i in range(n):
        if i % 500 == 0 and i < 1500:
            plan.append(([watched[(i // 500) % len(watched)]], "/camera/image_raw"))
            continue
        k = min(len(watched), rng.choice((1, 2, 3)))
        plan.append((rng.sample(watched, k), "/pose" if i % 10 == 1 else "/status"))
    return plan


async def window(tier: Tier, views: list[Child], seconds: float) -> dict[str, Any]:
    """Reset the viewers' counts, wait ``seconds``, return their merged stats."""
    await tier.broadcast(views, {"cmd": "reset"})
    await asyncio.sleep(seconds)
    return await tier.stats(views)


def _per(after: dict[str, dict[str, float]], before: dict[str, dict[str, float]], n: int,
         groups: tuple[str, ...] = ("relays", "routers")) -> dict[str, Any]:
    """KiB of RSS and % of a core per unit, by group."""
    return {g: {"kib": round((after[g]["rss_mib"] - before[g]["rss_mib"]) * 1024 / max(n, 1), 1),
                "cpu_pct": round((after[g]["cpu_pct"] - before[g]["cpu_pct"]) / max(n, 1), 4)}
            for g in groups}


async def measured(tier: Tier, seconds: float) -> dict[str, dict[str, float]]:
    """Usage over a window of ``seconds``."""
    tier.usage.start()
    await asyncio.sleep(seconds)
    return tier.usage.since()


async def run_size(ctx: Ctx, size: Size, folder: Path, churn_s: float,
                   out: dict[str, Any] | None = None) -> dict[str, Any]:
    """Every measurement of the module's text at one size, each put in ``out`` (returned)
    as it is made, so a caller that stops a size midway keeps what it measured."""
    tier = Tier(ctx, size, folder)
    out = {} if out is None else out
    out["size"] = str(size)
    win = 6.0 if ctx.quick else 10.0
    try:
        await tier.start()
        base = await measured(tier, win)
        t0 = time.monotonic()
        await tier.add_robots(tier.names)
        out["robots_join_s"] = round(time.monotonic() - t0, 1)  # until all hold their names
        await asyncio.sleep(3)
        idle = await measured(tier, win)
        out["per_unwatched_robot"] = _per(idle, base, size.robots)
        out["open_one"] = await open_one_by_one(tier, tier.names[-min(OPEN_ONE, size.robots):])
        watched = size.watched_names(tier.names)
        probes = await tier.add_viewers([([r], "/pose") for r in watched])
        one = await measured(tier, win)
        out["per_watched_robot"] = _per(one, idle, len(watched))
        pstats = await tier.stats(probes)
        out["open_robot_s"] = _q(pstats["open_s"])
        out["open_first_message_s"] = _q(pstats["first_s"])
        views = await tier.add_viewers(viewer_plan(watched, size.viewers))
        full = await measured(tier, win)
        out["per_viewer"] = _per(full, one, size.viewers)
        vstats = await tier.stats(views)
        out["viewer_open_s"] = _q(vstats["open_s"])
        out["viewer_first_message_s"] = _q(vstats["first_s"])
        out["viewers_silent"] = vstats["silent"]
        out["usage"] = full
        everyone = [*probes, *views]
        spy = await Profiler.maybe(ctx.profile, tier.relays[0].pid, win)
        lines = tier.relay_lines()
        out["steady"] = delivery(await window(tier, everyone, win))
        out["relay_lines"] = {"until_steady": lines, "in_steady": {
            k: v - lines[k] for k, v in tier.relay_lines().items()}}
        out["balancers"] = {"until_steady": await asyncio.to_thread(tier.balancer_counts)}
        if spy is not None:
            out["profile_relay_steady"] = await spy.result(20)
        spy = await Profiler.maybe(ctx.profile, tier.relays[0].pid, STATUS_PROFILE_S)
        out["relay_status_read"] = await status_read(tier)
        if spy is not None:
            out["profile_relay_status_read"] = await spy.result(20)
        out["flood"] = await flood(tier, everyone, watched, win)
        if size.relays > 1:
            out["relay_kill"] = await relay_kill(tier, everyone)
        out["router_restart"] = await router_restart(tier, everyone, profile=ctx.profile)
        out["churn"] = await churn(tier, churn_s)
        out["churn_again"] = await churn(tier, churn_s, prefix="churn2")
    except Exception as exc:  # what was measured before it stays in the report
        text = str(exc)  # its head says what failed, its tail how a child ended
        text = text if len(text) <= 6000 else f"{text[:1500]} [...] {text[-4500:]}"
        out["error"] = f"{type(exc).__name__}: {text}"
    finally:
        if "balancers" in out:  # what they did in all: the killed relay's viewers, the churn
            with contextlib.suppress(OSError, http.client.HTTPException):
                out["balancers"]["in_all"] = await asyncio.to_thread(tier.balancer_counts)
        await tier.stop()
    return out


async def status_read(tier: Tier) -> dict[str, Any]:
    """Seconds to read the first relay's ``/status.json`` with every viewer connected (what an
    operator's page waits for), and its size."""
    relay = tier.relays[0]
    t0 = time.monotonic()
    try:
        body = await asyncio.to_thread(get, f"http://127.0.0.1:{relay.port}/status.json", 60)
    except (OSError, http.client.HTTPException) as exc:  # a timeout, a page cut short
        return {"error": f"{type(exc).__name__}: {exc}", "s": round(time.monotonic() - t0, 2)}
    return {"s": round(time.monotonic() - t0, 3), "kib": round(len(body) / 1024, 1)}


async def open_one_by_one(tier: Tier, robots: list[str]) -> dict[str, Any]:
    """Each of ``robots`` opened through the balancer by one viewer, one after another, while
    nothing else opens a robot (the fleet's other robots idle): seconds to open it (the
    handshake: the relay finds the robot, fetches its graph and builds its types) and to its
    first ``/pose`` message. This is the target's figure; the probes' and viewers' open
    times measure many robots opened at once, each waiting for the others."""
    from bench.fleetview import Conn

    opens, firsts = [], []
    for name in robots:
        conn = Conn(tier.url, name, "/pose")
        task = asyncio.create_task(conn.run())
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(conn.heard.wait(), 30)
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
        opens += [conn.open_s] if conn.open_s is not None else []
        firsts += [conn.first_s] if conn.first_s is not None else []
    return {"robots": len(robots), "opened": len(opens), "open_s": _q(opens),
            "first_message_s": _q(firsts)}


async def flood(tier: Tier, views: list[Child], watched: list[str], seconds: float
                ) -> dict[str, Any]:
    """One watched robot floods two viewers; the others' delivery against a window without."""
    loud = watched[0]
    before = delivery(await window(tier, views, seconds), frozenset({loud}))
    sim = tier.sim_of(loud)
    await sim.command({"cmd": "flood", "robot": loud, "bytes": 100_000, "hz": 100})
    flooders = await tier.add_viewers([([loud], "/flood")] * 2, wait=30)
    during = delivery(await window(tier, views, seconds), frozenset({loud}))
    got = (await tier.stats(flooders))["robots"].get(loud, {}).get("frames", 0)
    await sim.command({"cmd": "flood", "robot": loud, "hz": 0})
    for f in flooders:
        await f.stop()
        tier.viewers.remove(f)
    return {"flooding_robot_frames_per_s": round(got / 2 / seconds, 1),
            "others_without": before, "others_during": during}


async def relay_kill(tier: Tier, views: list[Child], limit: float = 60.0) -> dict[str, Any]:
    """The last relay SIGKILLed: seconds until each viewer connection hears its robot."""
    t = time.time()
    await tier.broadcast(views, {"cmd": "mark", "t": t})
    tier.relays[-1].proc.kill()  # type: ignore[union-attr]
    return await _until_back(tier, views, limit)


async def _until_back(tier: Tier, views: list[Child], limit: float) -> dict[str, Any]:
    deadline = time.monotonic() + limit
    while True:
        s = await tier.stats(views)
        back = [b for b in s["back_s"] if b is not None]
        if len(back) == len(s["back_s"]) or time.monotonic() > deadline:
            return {"viewers_back_s": _q(back), "not_back": len(s["back_s"]) - len(back)}
        await asyncio.sleep(1)


async def router_restart(tier: Tier, views: list[Child], down: float = 2.0,
                         limit: float = 60.0, profile: bool = False) -> dict[str, Any]:
    """Router 0 SIGKILLed, restarted on its port ``down`` s later: seconds from the restart
    until every robot holds its name again (and how many each robot process held at the
    last look), and until each viewer hears its robot. With ``profile`` (``--profile``),
    py-spy on the first relay and the first robot process for the first
    :data:`RESTART_PROFILE_S` seconds after the restart."""
    router = tier.routers[0]
    assert router is not None
    router.kill()
    await asyncio.sleep(down)
    await tier.start_router(0)
    t = time.time()
    spies = {name: await Profiler.maybe(profile, pid, RESTART_PROFILE_S)
             for name, pid in (("relay", tier.relays[0].pid), ("robots", tier.sims[0].pid))}
    await tier.broadcast(views, {"cmd": "mark", "t": t})
    robots_back = None
    deadline = time.monotonic() + limit
    held: list[int] = []
    while robots_back is None and time.monotonic() < deadline:
        held = [(await sim.command({"cmd": "stats"}))["holding"] for sim in tier.sims]
        if sum(held) >= len(tier.names):
            robots_back = round(time.time() - t, 2)
        else:
            await asyncio.sleep(0.5)
    back = await _until_back(tier, views, limit)
    profiles = {f"profile_{name}": await spy.result(20) for name, spy in spies.items()
                if spy is not None}
    return {"robots_back_s": robots_back, "holding_by_process": held, **back, **profiles}


async def churn(tier: Tier, seconds: float, prefix: str = "churn") -> dict[str, Any]:
    """Robots joining and leaving, one more a second for ``seconds`` (each its own life: it
    joins, a viewer opens it through the balancer and hears it, it leaves; lives overlap),
    named ``PREFIX-<n>``: relay RSS and the robots the relays list, before and after the
    relays forgot those that left; and, for comparison, how much the relays' RSS moved in
    the :data:`CHURN_CONTROL_S` s (at most ``seconds``) just before, without churn."""
    def listed() -> int:  # the robots the relays list, and those they are letting go of
        return sum(len(s["robots"]) + s.get("forgetting", 0) for s in tier.relay_status())

    # the same time without churn first: what the relays' memory does on its own then (the
    # step before, a router's restart, may leave it moving)
    quiet = min(seconds, CHURN_CONTROL_S)
    rss0 = tier.usage.since()["relays"]["rss_mib"]
    await asyncio.sleep(quiet)
    before = {"rss_mib": tier.usage.since()["relays"]["rss_mib"], "robots_listed": listed()}
    drift = round(100 * (before["rss_mib"] / rss0 - 1), 1)
    sim = Child(["bench.simrobot", "--connect", tier.router_eps[-1], "--count", "0",
                 "--prefix", prefix], tier.ctx.domain, prefix)
    await sim.start()
    tier.sims.append(sim)
    await sim.event(60)
    from bench.fleetview import Conn

    lock = asyncio.Lock()  # one command at a time: each answer is the next line

    async def ask(cmd: dict[str, Any]) -> None:
        async with lock:
            await sim.command(cmd)

    async def life(name: str) -> bool:
        await ask({"cmd": "join", "robot": name, "wait": 0})
        conn = Conn(tier.url, name, "/pose")  # dials again until the relays know the robot
        task = asyncio.create_task(conn.run())
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(conn.heard.wait(), 30)
        task.cancel()
        await ask({"cmd": "leave", "robot": name})
        return conn.heard.is_set()

    lives: list[asyncio.Task[bool]] = []
    start = time.monotonic()
    while time.monotonic() - start < seconds:
        lives.append(asyncio.create_task(life(f"{prefix}-{len(lives)}")))
        await asyncio.sleep(max(0.0, start + len(lives) - time.monotonic()))
    heard = sum(await asyncio.gather(*lives))
    deadline = time.monotonic() + 90  # a viewer's kept session, two looks of the relays'
    while listed() > before["robots_listed"] and time.monotonic() < deadline:  # forgetting
        await asyncio.sleep(1)
    after = {"rss_mib": tier.usage.since()["relays"]["rss_mib"], "robots_listed": listed()}
    return {"robots": len(lives), "heard": heard, "seconds": round(time.monotonic() - start),
            "before": before, "after": after,
            "rss_drift_pct_without_churn": {"seconds": quiet, "pct": drift},
            "rss_growth_pct": round(100 * (after["rss_mib"] / before["rss_mib"] - 1), 1)}


async def fleet(ctx: Ctx) -> dict[str, Any]:
    """The ``fleet`` scenario (see the module's text)."""
    churn_s = 30.0 if ctx.quick else 300.0
    results = []
    with tempfile.TemporaryDirectory(prefix="fleet-") as folder:
        for size in sizes(ctx):
            results.append(await run_size(ctx, size, Path(folder), churn_s))
    return {"sizes": results}
