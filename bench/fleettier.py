"""The fleet's processes at one size (``bench/fleet.py`` measures them): Zenoh routers in a
mesh, relays behind HAProxy, simulated robots and viewers, each a child process
(:class:`~bench.fleetproc.Child`); :class:`Size` names a size, :class:`Tier` starts, asks
and stops its processes."""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bench.fleetproc import Balancer, Child, Usage, get, haproxy_config, node_viewers
from bench.harness import Bridge, Ctx
from bench.ports import free_port
from bench.relay import RELAY_READY

__all__ = ["BALANCER_CONNECTIONS", "JOIN_WAIT", "PER_PROCESS", "QUICK", "RELAY_LINES", "SIZES",
           "Size", "Tier", "sizes"]

JOIN_WAIT = 900
"""Seconds a robot process waits for all its robots to hold their names (250 robots on
this loaded machine took more than the robots' own 120 s)."""
PER_PROCESS = 250
"""Simulated robots per process."""
RELAY_LINES = {"connected": "connected from", "disconnected": ") disconnected",
               "keepalive_dropped": "no sign of it"}
"""Lines counted in the relays' logs (reported with each window): clients connected and
gone, and those the keepalive dropped as silent."""
VIEWERS_PER_PROCESS = 1500
"""Viewer connections per Python process (``bench/fleetview.py``)."""
NODE_VIEWERS_PER_PROCESS = 4000
"""Viewer connections per Node process (``bench/fleetview.mjs``, used when Node and its
``ws`` package are here, unless ``BENCH_FLEET_VIEWERS=python``): some 10,000 connections
took 32 % of a core in Node, 66 % in Python while hearing far fewer messages, so that the
viewers leave the machine to the tier they measure."""
BALANCER_CONNECTIONS = 9000
"""Viewer connections per HAProxy: each takes two of its descriptors, and a process here may
open at most 20,000 (``ulimit -Hn``, which this machine does not let even root raise). A
size with more viewer connections gets more balancers before the same relays, each viewer
process dialing one of them (as a site gives two balancers one name by DNS)."""


@dataclass(frozen=True)
class Size:
    """One size of the fleet."""

    robots: int
    routers: int
    relays: int
    viewers: int
    watched: int = 0
    """Robots the viewers watch (0: a tenth of the viewers, at most all robots). Each watched
    robot's messages reach every relay that has a viewer of it, so on this 2-core machine
    5,000 viewers fit only over fewer robots than 500 (``1000x2x2x5000x100``)."""

    def __str__(self) -> str:
        tail = f"x{self.watched}" if self.watched else ""
        return f"{self.robots}x{self.routers}x{self.relays}x{self.viewers}{tail}"

    @property
    def watched_robots(self) -> int:
        """How many robots the viewers watch (see :attr:`watched`)."""
        return max(1, min(self.robots, self.watched or self.viewers // 10))

    def watched_names(self, names: list[str]) -> list[str]:
        """The robots of ``names`` the viewers watch: :attr:`watched_robots` of them, spread
        evenly over the list, so over the robot processes (each runs :data:`PER_PROCESS` in
        turn) as a fleet's watched robots are over its machines. The first 100 of 1,000
        were 100 putting threads in one process of 250 robots, whose loop then spent 44 % of
        its samples handing Python's lock to them (after a router's restart)."""
        return names[::max(1, len(names) // self.watched_robots)][:self.watched_robots]


SIZES = (Size(10, 1, 1, 100), Size(100, 2, 2, 1000), Size(500, 2, 4, 1000),
         Size(1000, 2, 2, 5000, 100))
QUICK = (Size(10, 1, 2, 100),)


def sizes(ctx: Ctx) -> tuple[Size, ...]:
    """The sizes to run: ``BENCH_FLEET_SIZES`` if set, else :data:`QUICK` or :data:`SIZES`."""
    given = os.environ.get("BENCH_FLEET_SIZES")
    if given:
        try:
            return tuple(Size(*(int(x) for x in s.split("x"))) for s in given.split(","))
        except (TypeError, ValueError):
            raise ValueError(f"BENCH_FLEET_SIZES={given!r}: expected robots x routers x relays "
                             "x viewers [x watched], comma-separated, e.g. 100x2x2x1000"
                             ) from None
    return QUICK if ctx.quick else SIZES


class Tier:
    """Routers, relays, HAProxy and the robot processes of one size; stopped on exit."""

    def __init__(self, ctx: Ctx, size: Size, folder: Path, prefix: str = "sim",
                 relay_args: tuple[str, ...] = ()) -> None:
        """``relay_args``: more command-line arguments of every relay."""
        self.ctx, self.size, self.folder, self.prefix = ctx, size, folder, prefix
        self.relay_args = list(relay_args)
        self.router_eps = [f"tcp/127.0.0.1:{free_port()}" for _ in range(size.routers)]
        self.routers: list[Child | None] = [None] * size.routers
        self.relays: list[Bridge] = []
        self.sims: list[Child] = []
        self.viewers: list[Child] = []
        self.balancers: list[Balancer] = []
        self.names = [f"{prefix}-{i}" for i in range(size.robots)]
        self.usage = Usage(self._pids)

    def _pids(self) -> dict[str, list[int]]:
        def alive(ps: list[Any]) -> list[int]:
            return [p.proc.pid for p in ps if p is not None and p.proc is not None
                    and p.proc.returncode is None]

        return {"routers": alive(self.routers), "relays": alive(self.relays),
                "robots": alive(self.sims), "viewers": alive(self.viewers),
                "balancers": alive(self.balancers)}

    @property
    def url(self) -> str:
        """The first balancer's websocket address."""
        return self.url_of(0)

    def url_of(self, i: int) -> str:
        """The websocket address of balancer ``i`` (modulo their number)."""
        assert self.balancers
        return f"ws://127.0.0.1:{self.balancers[i % len(self.balancers)].port}"

    async def start_router(self, i: int) -> None:
        """Router ``i`` (listening on its endpoint; the others dial router 0)."""
        mesh = [] if i == 0 else ["--connect", self.router_eps[0]]
        router = Child(["bench.zrouter", "--listen", self.router_eps[i], *mesh],
                       self.ctx.domain, f"router{i}")
        await router.start()
        self.routers[i] = router
        await _ready_line(router)

    async def start(self) -> None:
        """Routers, relays, the balancers (robots: :meth:`add_robots`): one per
        :data:`BALANCER_CONNECTIONS` viewer connections the size may open (each viewer
        watches two robots on average, and a tenth of the viewers' count of probes)."""
        for i in range(self.size.routers):
            await self.start_router(i)
        connections = 2 * self.size.viewers + self.size.watched_robots
        # a relay serves --max-clients connections (1,000 by default) and refuses the rest
        # (503): room for twice its share, so that a killed relay's viewers fit on the others
        share = max(1000, 2 * math.ceil(connections / self.size.relays))
        for i in range(self.size.relays):
            relay = Bridge(self.ctx.domain, ["--zenoh-connect",
                                             self.router_eps[i % self.size.routers],
                                             "--max-clients", str(share), *self.relay_args],
                           self.ctx.bridge_root, module="bridge_server.zenoh.relay",
                           ready=RELAY_READY)
            relay.counting = dict(RELAY_LINES)
            self.relays.append(await relay.start(60))
        for i in range(max(1, math.ceil(connections / BALANCER_CONNECTIONS))):
            port, stats_port = free_port(), free_port()
            folder = self.folder / f"balancer{i}"
            folder.mkdir(exist_ok=True)
            self.balancers.append(await Balancer(
                haproxy_config(port, [r.port for r in self.relays], stats_port), folder, port,
                stats_port).start())

    async def add_robots(self, names: list[str]) -> list[Child]:
        """Robot processes for ``names`` (:data:`PER_PROCESS` each), dialing the routers in
        turn; returned once every robot holds its name."""
        made = []
        for k in range(0, len(names), PER_PROCESS):
            chunk = names[k:k + PER_PROCESS]
            first = int(chunk[0].rsplit("-", 1)[1])
            sim = Child(["bench.simrobot", "--connect",
                         self.router_eps[len(self.sims) % self.size.routers],
                         "--count", str(len(chunk)), "--first", str(first),
                         "--prefix", chunk[0].rsplit("-", 1)[0], "--wait", str(JOIN_WAIT)],
                        self.ctx.domain,
                        f"robots{len(self.sims)}")
            await sim.start()
            self.sims.append(sim)
            made.append(sim)
        for sim in made:
            ready = await sim.event(JOIN_WAIT + 60)
            if ready.get("missing"):
                raise RuntimeError(f"{len(ready['missing'])} robots never held their names "
                                   f"in {JOIN_WAIT} s: {ready['missing'][:5]}; {sim.name} "
                                   "said last:\n" + "\n".join(sim.lines))
        return made

    def sim_of(self, robot: str) -> Child:
        """The process that runs ``robot`` (of :attr:`names`)."""
        return self.sims[self.names.index(robot) // PER_PROCESS]

    async def add_viewers(self, plan: list[tuple[list[str], str]], wait: float = 180.0
                          ) -> list[Child]:
        """Viewer processes for ``plan`` (each entry one viewer: its robots and topic);
        returned once each connection heard its robot (or ``wait`` passed)."""
        made = []
        chunk: list[tuple[list[str], str]] = []
        chunks = []
        node = os.environ.get("BENCH_FLEET_VIEWERS", "node") == "node" and node_viewers()
        program = "bench/fleetview.mjs" if node else "bench.fleetview"
        per_process = NODE_VIEWERS_PER_PROCESS if node else VIEWERS_PER_PROCESS
        for entry in plan:
            if sum(len(r) for r, _ in chunk) + len(entry[0]) > per_process:
                chunks.append(chunk)
                chunk = []
            chunk.append(entry)
        chunks.append(chunk)
        for part in chunks:
            view = Child([program, self.url_of(len(self.viewers)), json.dumps(part),
                          "--wait", str(wait)],
                         self.ctx.domain, f"viewers{len(self.viewers)}")
            await view.start()
            self.viewers.append(view)
            made.append(view)
        for view in made:
            await view.event(wait + 120)
        return made

    async def stats(self, views: list[Child]) -> dict[str, Any]:
        """Every viewer process's stats, merged."""
        merged: dict[str, Any] = {"robots": {}, "open_s": [], "first_s": [], "back_s": [],
                                  "silent": 0, "reconnects": 0, "odd": None}
        for view in views:
            s = await view.command({"cmd": "stats"})
            for k in ("open_s", "first_s", "back_s"):
                merged[k] += s[k]
            merged["silent"] += s["silent"]
            merged["reconnects"] += s["reconnects"]
            merged["odd"] = merged["odd"] or s.get("odd")
            for robot, r in s["robots"].items():
                m = merged["robots"].setdefault(robot, {"got": 0, "missed": 0, "repeated": 0,
                                                        "frames": 0, "malformed": 0,
                                                        "latency_ms": [], "viewers": 0})
                for k in ("got", "missed", "repeated", "frames", "malformed", "viewers"):
                    m[k] += r[k]
                m["latency_ms"] += r["latency_ms"]
        return merged

    async def broadcast(self, views: list[Child], cmd: dict[str, Any]) -> None:
        """Send ``cmd`` to each of ``views``."""
        for view in views:
            await view.command(cmd)

    def relay_lines(self) -> dict[str, int]:
        """:data:`RELAY_LINES` counted in every relay's log so far."""
        return {label: sum(r.counted[label] for r in self.relays) for label in RELAY_LINES}

    def balancer_counts(self) -> dict[str, Any]:
        """The balancers' :meth:`~bench.fleetproc.Balancer.counts`, summed: connections
        taken, passed to each relay, and passed to none; each relay's times marked down and
        seconds down (the most any balancer saw)."""
        total: dict[str, Any] = {"sessions": 0, "to_no_relay": 0, "relays": {}}
        for balancer in self.balancers:
            c = balancer.counts()
            total["sessions"] += c["sessions"]
            total["to_no_relay"] += c["to_no_relay"]
            for name, r in c["relays"].items():
                t = total["relays"].setdefault(name, {"sessions": 0, "went_down": 0,
                                                      "down_s": 0, "status": r["status"]})
                t["sessions"] += r["sessions"]
                t["went_down"] = max(t["went_down"], r["went_down"])
                t["down_s"] = max(t["down_s"], r["down_s"])
        return total

    def relay_status(self) -> list[dict[str, Any]]:
        """Each live relay's ``/status.json``."""
        out = []
        for relay in self.relays:
            if relay.proc is not None and relay.proc.returncode is None:
                out.append(json.loads(get(f"http://127.0.0.1:{relay.port}/status.json", 30)))
        return out

    async def stop(self) -> None:
        """Everything, viewers first."""
        for child in [*self.viewers, *self.sims]:
            with contextlib.suppress(Exception):
                await child.stop()
        for balancer in self.balancers:
            await balancer.stop()
        for relay in self.relays:
            with contextlib.suppress(Exception):
                await relay.stop()
        for router in self.routers:
            if router is not None:
                with contextlib.suppress(Exception):
                    await router.stop()


async def _ready_line(router: Child) -> None:
    """Wait for the router's ``zenoh router ready`` line."""
    deadline = time.monotonic() + 30
    while not any("zenoh router ready" in line for line in router.lines):
        if router.proc is None or router.proc.returncode is not None:
            raise RuntimeError("router exited:\n" + "\n".join(router.lines))
        if time.monotonic() > deadline:
            raise RuntimeError("router not ready:\n" + "\n".join(router.lines))
        await asyncio.sleep(0.05)
