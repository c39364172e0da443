"""A topic's advanced publisher (robot) or subscriber (relay) is undeclared off the event loop,
and leaves nothing behind (issue 49).

Undeclaring a ``zenoh.ext`` advanced entity waits for its tasks to end, up to 10 s when
Zenoh's threads are busy, some of them waiting for the loop. In the fleet benchmark (250
simulated robots a process, 5,000 viewers) a robot process's loop sat in
``ReplayPublisher.close`` at each topic a relay stopped watching, 10 s each time, and its
robots answered nothing for minutes. Here the publisher's undeclaration is held until the
test lets it go: closing returns at once, and the undeclaration runs on another thread.

An advanced subscriber declared with a bare callable is kept "in the background" by Zenoh:
undeclared, it left its heartbeat subscriber and its state, holding the relay's callback,
for the session's life (some 1.7 KB at each topic a relay stopped watching).
"""

from __future__ import annotations

import gc
import threading
import weakref
from typing import Any

from bridge_server.zenoh.inbox import direct
from bridge_server.zenoh.replay import (
    ReplayBudget,
    ReplayPublisher,
    ReplayWindow,
    recovering_subscriber,
    settle_aside,
    undeclare_aside,
)
from tests.relay.support import lone_session

HOLD = 30.0
"""Seconds the held undeclaration waits for the test at most (so a broken build fails, not
hangs)."""


class _Told:
    """What the test keeps of a :class:`_Held`: when and where it was let go."""

    def __init__(self) -> None:
        self.release = threading.Event()
        self.done = threading.Event()
        self.thread: int | None = None


class _Held:
    """An advanced publisher whose undeclaration (its last reference going) waits until the
    test releases it; the publisher goes with it."""

    def __init__(self, pub: Any, told: _Told) -> None:
        self.pub = pub
        self.told = told

    def put(self, *args: Any, **kwargs: Any) -> None:
        self.pub.put(*args, **kwargs)

    def __del__(self) -> None:
        self.told.thread = threading.get_ident()
        self.told.release.wait(HOLD)
        self.told.done.set()


def test_closing_a_replayed_topic_does_not_wait_for_its_undeclaration() -> None:
    """A real advanced publisher on a real Zenoh session (alone: no scouting, no endpoints),
    its undeclaration held: ``close`` returns before it ran, it runs on another thread than
    the caller's, and it does run once let go (:func:`settle_aside` waits for it, as the
    session's closing does); the window's room is given back at once."""
    with lone_session() as session:
        window = ReplayWindow(count=10, bytes=1000, total=1000)
        budget = ReplayBudget(window.total)
        topic = ReplayPublisher(session, "r/a", window, "/a", budget)
        topic.put(b"x" * 10, b"{}")
        told = _Told()
        topic._pub = _Held(topic._pub, told)
        topic.close()
        assert told.thread != threading.get_ident(), "undeclared on the caller's thread"
        assert not told.done.is_set()
        assert budget.reserved == 0
        assert not settle_aside(0.1), "settled with an undeclaration still held"
        told.release.set()
        assert settle_aside(HOLD), "the undeclaration never ran"
        assert told.done.is_set()
        assert told.thread is not None and told.thread != threading.get_ident()


def test_a_recovering_subscriber_leaves_nothing_behind() -> None:
    """A relay's recovering subscriber with a heartbeat starts no Python thread (its miss
    listener's callback on Zenoh's thread); undeclared aside, once the aside thread is past
    it, nothing refers to its callbacks any more (in the background, its heartbeat
    subscriber kept them for the session's life)."""
    with lone_session() as session:
        def on_sample(sample: Any) -> None:
            pass

        def on_miss(n: int) -> None:
            pass

        sample_ref, miss_ref = weakref.ref(on_sample), weakref.ref(on_miss)
        undeclare_aside([])  # the aside thread started before the count
        threads = threading.active_count()
        entities = recovering_subscriber(session, "r/a", direct(on_sample), on_miss)
        assert threading.active_count() == threads, "a Python thread for its callbacks"
        del on_sample, on_miss
        told = _Told()
        told.release.set()
        entities.append(_Held(None, told))  # let go after them, in order
        undeclare_aside(entities)
        assert entities == []
        assert told.done.wait(HOLD), "the aside thread never came to the marker"
        gc.collect()
        assert sample_ref() is None, "something still holds the subscriber's callback"
        assert miss_ref() is None, "something still holds the miss listener's callback"
