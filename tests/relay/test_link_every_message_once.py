"""Every message once, in order, through repeated cuts of a robot's link (issue 49, item 4).

A reliable counter at 100 Hz on a robot (:mod:`tests.relay.link_load`), its link cut
(blackholed past the lease, so the relay tells its clients the robot went away) again and
again, the replay window large enough for each cut: our client, stock roslibpy and (where
npm's packages are) the Foxglove client hear every number exactly once and in order.
"""

from __future__ import annotations

import asyncio
import itertools
from collections.abc import Callable

import pytest

from rosbridge_core.protocol import ops
from tests.relay.link_load import load_tier
from tests.relay.support import until
from tests.relay.test_relay_outage import clients

pytestmark = pytest.mark.timeout(240)

CUTS = 3


def _wrong(numbers: list[int]) -> list[tuple[int, int]]:
    """(after, next) wherever ``numbers`` does not go on by one: a repeat, a gap or a step
    back."""
    return [(a, b) for a, b in itertools.pairwise(numbers) if b != a + 1]


def _told(statuses: list[ops.Status], what: str, times: int) -> Callable[[], bool]:
    """Whether ``times`` (or more) of our client's statuses say ``what``."""
    return lambda: sum(what in s.msg for s in statuses) >= times


async def test_every_number_arrives_once_and_in_order_through_repeated_cuts() -> None:
    """Three cuts of the robot's link past the lease while a 100 Hz reliable counter runs
    (window 2,000): each client hears every number from its first once, in order, up to one
    published after the last cut."""
    with load_tier("--relay-replay-count", "2000", hz=100.0) as t:
        async with clients(t) as (heard, statuses, _fox):
            ours = heard["roslibpy_lite"]
            for cut in range(1, CUTS + 1):
                t.link.blackhole()
                try:
                    await until(_told(statuses, "went away:", cut),
                                f"cut {cut}: the relay to tell the robot went away", 20)
                    await asyncio.sleep(1.0)  # past the lease, the counter going on
                finally:
                    t.link.restore()
                await until(_told(statuses, "is back: its topics flow again", cut),
                            f"cut {cut}: the relay to tell the robot is back", 30)
                flowing = t.sent() + 100  # the robot's link is whole again
                await until(lambda n=flowing: ours()[-1] >= n,
                            f"cut {cut}: our client to hear {flowing}", 30)
            last = t.sent() + 100
            await until(lambda: all(h() and h()[-1] >= last for h in heard.values()),
                        f"every client to hear {last}", 60)
            for name, h in heard.items():
                numbers = h()
                end = numbers.index(last) + 1
                assert _wrong(numbers[:end]) == [], (name, _wrong(numbers[:end]))
