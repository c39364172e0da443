"""A relay forgets a robot that left and that nobody waits for, and only such a robot."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

from bridge_server.zenoh.forget import Forgetter


class _Graph:
    def __init__(self, here: bool) -> None:
        self.here = here

    def trouble(self) -> str | None:
        return None if self.here else "gone"


def _bridge(here: bool, sessions: int = 0) -> Any:
    closed: list[bool] = []

    async def close() -> None:
        closed.append(True)

    return SimpleNamespace(graph=_Graph(here), sessions=set(range(sessions)),
                           foxglove=SimpleNamespace(sessions=set()), close=close,
                           closed=closed)


async def test_gone_and_unwatched_robots_are_forgotten_at_the_second_look() -> None:
    """A robot away with no session goes at the second look in a row (closed); one present,
    or away with a session (kept for a resume too), stays; one back between looks stays."""
    robots: dict[str, Any] = {"gone": _bridge(False), "here": _bridge(True),
                              "waited": _bridge(False, sessions=1), "back": _bridge(False)}
    gone = robots["gone"]
    forgetter = Forgetter(robots)
    await forgetter.sweep()
    assert set(robots) == {"gone", "here", "waited", "back"}
    robots["back"].graph.here = True
    await forgetter.sweep()
    assert set(robots) == {"here", "waited", "back"}
    assert gone.closed == [True] and forgetter.forgotten == 1
    robots["back"].graph.here = False
    await forgetter.sweep()
    assert "back" in robots  # away again: one look more first
    await forgetter.sweep()
    assert set(robots) == {"here", "waited"}


async def test_a_forgotten_robot_in_reference_cycles_is_freed_at_the_look() -> None:
    """A forgotten robot's bridge in a reference cycle (as a real one is) is freed by the look
    that forgot it, with the collector's own thresholds off (issue 49)."""
    import gc
    import weakref

    class Held:
        """Stands for the native memory a closed robot's objects hold."""

    bridge = _bridge(False)
    bridge.held = Held()
    bridge.me = bridge  # a cycle
    held = weakref.ref(bridge.held)
    robots: dict[str, Any] = {"gone": bridge}
    del bridge
    forgetter = Forgetter(robots)
    was = gc.isenabled()
    gc.disable()
    try:
        await forgetter.sweep()
        await forgetter.sweep()
    finally:
        if was:
            gc.enable()
    assert robots == {} and held() is None, "the forgotten robot's cycle was kept"
