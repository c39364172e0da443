"""A topic's advanced publisher (robot) or subscriber (relay) is undeclared off the event loop
(issue 49).

Undeclaring a ``zenoh.ext`` advanced entity waits for its tasks to end, up to 10 s when
Zenoh's threads are busy, some of them waiting for the loop. In the fleet benchmark (250
simulated robots a process, 5,000 viewers) a robot process's loop sat in
``ReplayPublisher.close`` at each topic a relay stopped watching, 10 s each time, and its
robots answered nothing for minutes. Here the publisher's undeclaration is held until the
test lets it go: closing returns at once, and the undeclaration runs on another thread.
"""

from __future__ import annotations

import threading
from typing import Any

from bridge_server.zenoh.replay import ReplayBudget, ReplayPublisher, ReplayWindow
from tests.relay.support import lone_session

HOLD = 30.0
"""Seconds the held undeclaration waits for the test at most (so a broken build fails, not
hangs)."""


class _Held:
    """An advanced publisher whose undeclaration waits until released (then undeclares it)."""

    def __init__(self, pub: Any) -> None:
        self.pub = pub
        self.release = threading.Event()
        self.done = threading.Event()
        self.thread: int | None = None

    def put(self, *args: Any, **kwargs: Any) -> None:
        self.pub.put(*args, **kwargs)

    def undeclare(self) -> None:
        self.thread = threading.get_ident()
        self.release.wait(HOLD)
        self.pub.undeclare()
        self.done.set()


def test_closing_a_replayed_topic_does_not_wait_for_its_undeclaration() -> None:
    """A real advanced publisher on a real Zenoh session (alone: no scouting, no endpoints),
    its undeclaration held: ``close`` returns before it ran, it runs on another thread than
    the caller's, and it does run once let go; the window's room is given back at once."""
    with lone_session() as session:
        window = ReplayWindow(count=10, bytes=1000, total=1000)
        budget = ReplayBudget(window.total)
        topic = ReplayPublisher(session, "r/a", window, "/a", budget)
        topic.put(b"x" * 10, b"{}")
        held = _Held(topic._pub)
        topic._pub = held
        topic.close()
        assert held.thread != threading.get_ident(), "undeclared on the caller's thread"
        assert not held.done.is_set()
        assert budget.reserved == 0
        held.release.set()
        assert held.done.wait(HOLD), "the undeclaration never ran"
        assert held.thread is not None and held.thread != threading.get_ident()
