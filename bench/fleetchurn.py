"""Churn alone, in rounds (``python -m bench.fleetchurn``): what the relay keeps of robots
that joined and left (issue 49), without the rest of the fleet scenario.

One router, one relay, HAProxy; each round :func:`bench.fleet.churn` (robots joining and
leaving one a second, each opened by a viewer, then forgotten by the relay); after each
round the relay's RSS, anonymous memory and thread count from ``/proc``. Prints one JSON
line per round. Nothing here asserts anything.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import signal
import tempfile
from pathlib import Path
from typing import Any

from bench.fleet import churn
from bench.fleettier import Size, Tier
from bench.harness import Ctx

__all__ = ["proc_memory", "rounds"]


def proc_memory(pid: int) -> dict[str, float]:
    """Process ``pid``'s RSS and anonymous memory (MiB) and thread count, from ``/proc``."""
    out: dict[str, float] = {}
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        key, _, value = line.partition(":")
        if key in ("VmRSS", "RssAnon"):
            out[key] = round(int(value.split()[0]) / 1024, 1)
        elif key == "Threads":
            out[key] = int(value)
    return out


async def rounds(ctx: Ctx, n: int, seconds: float, poke: bool = False) -> list[dict[str, Any]]:
    """``n`` churn rounds of ``seconds`` each against one relay; its memory after each
    (``poke``: and a SIGUSR1 to the relay then, for a dump hook of one's own, e.g. tracemalloc's
    snapshot from a ``sitecustomize`` on ``PYTHONPATH``)."""
    results = []
    with tempfile.TemporaryDirectory(prefix="fleetchurn-") as folder:
        tier = Tier(ctx, Size(0, 1, 1, 0), Path(folder))
        try:
            await tier.start()
            tier.usage.start()
            pid = tier.relays[0].pid
            if poke:
                os.kill(pid, signal.SIGUSR1)
            results.append({"round": 0, **proc_memory(pid)})
            print(json.dumps(results[-1]), flush=True)
            for i in range(1, n + 1):
                c = await churn(tier, seconds, prefix=f"churn{i}")
                results.append({"round": i, "robots": c["robots"], "heard": c["heard"],
                                "listed": c["after"]["robots_listed"], **proc_memory(pid)})
                if poke:
                    os.kill(pid, signal.SIGUSR1)
                print(json.dumps(results[-1]), flush=True)
        finally:
            await tier.stop()
    return results


def main() -> None:
    """The command line."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3, help="churn rounds")
    ap.add_argument("--seconds", type=float, default=30.0, help="seconds of each round")
    ap.add_argument("--poke", action="store_true",
                    help="send the relay SIGUSR1 after each round (a dump hook of one's own)")
    a = ap.parse_args()
    ctx = Ctx(duration=a.seconds, quick=True, domain=int(os.environ.get("ROS_DOMAIN_ID", "0")),
              profile=False)
    asyncio.run(rounds(ctx, a.rounds, a.seconds, a.poke))


if __name__ == "__main__":
    main()
