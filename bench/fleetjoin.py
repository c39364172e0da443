"""Robots joining, then viewers opening and closing them in rounds (``python -m
bench.fleetjoin``): how long the simulated robots take to hold their names, each robot
process's threads, and whether every robot process still answers after each round (issue
49: the stalls of ``docs/guides/sizing-log.md``). One router, HAProxy before the relays. Prints
one JSON line per step. Nothing here asserts anything.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import tempfile
import time
from pathlib import Path
from typing import Any

from bench.fleetchurn import proc_memory
from bench.fleettier import Size, Tier
from bench.harness import Ctx

__all__ = ["ANSWER_WAIT", "rounds"]

ANSWER_WAIT = 30.0
"""Seconds a robot process has to answer after a round before it counts as stalled."""


def _say(line: dict[str, Any]) -> dict[str, Any]:
    print(json.dumps(line), flush=True)
    return line


async def rounds(ctx: Ctx, robots: int, relays: int, n: int, watched: int
                 ) -> list[dict[str, Any]]:
    """``robots`` robots join; then ``n`` rounds of a ``/pose`` and a ``/status`` viewer of
    each of the first ``watched`` robots, opened until each heard (60 s at most) and closed.
    Returns the lines printed."""
    out = []
    with tempfile.TemporaryDirectory(prefix="fleetjoin-") as folder:
        tier = Tier(ctx, Size(robots, 1, relays, 0), Path(folder))
        try:
            await tier.start()
            t0 = time.monotonic()
            await tier.add_robots(tier.names)
            out.append(_say({"step": "joined", "robots": robots,
                             "join_s": round(time.monotonic() - t0, 1),
                             "sims": [proc_memory(sim.pid) for sim in tier.sims]}))
            names = tier.names[:watched]
            for i in range(1, n + 1):
                t0 = time.monotonic()
                views = await tier.add_viewers(
                    [([r], topic) for r in names for topic in ("/pose", "/status")], wait=60)
                opened = round(time.monotonic() - t0, 1)
                stats = await tier.stats(views)
                heard = sum(1 for r in stats["robots"].values() if r["got"])
                for view in views:
                    await view.stop()
                    tier.viewers.remove(view)
                stalled = []
                for sim in tier.sims:
                    try:
                        await sim.command({"cmd": "stats"}, timeout=ANSWER_WAIT)
                    except (TimeoutError, RuntimeError):
                        stalled.append(sim.pid)
                out.append(_say({"step": "round", "round": i, "opened_s": opened,
                                 "robots_heard": heard, "of": len(names),
                                 "stalled_pids": stalled,
                                 "sims": [proc_memory(sim.pid) for sim in tier.sims]}))
        finally:
            await tier.stop()
    return out


def main() -> None:
    """The command line."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", type=int, default=250, help="simulated robots")
    ap.add_argument("--relays", type=int, default=2, help="relays behind HAProxy")
    ap.add_argument("--rounds", type=int, default=4, help="rounds of viewers")
    ap.add_argument("--watched", type=int, default=250, help="robots the viewers open")
    a = ap.parse_args()
    ctx = Ctx(duration=10.0, quick=True, domain=int(os.environ.get("ROS_DOMAIN_ID", "0")),
              profile=False)
    asyncio.run(rounds(ctx, a.robots, a.relays, a.rounds, a.watched))


if __name__ == "__main__":
    main()
