"""A relay's Zenoh callbacks that only hand to the loop run on Zenoh's own thread (issue 49).

A plain Python callable given to zenoh-python gets a Python thread of its own per
subscriber, queryable or query, started with it and ended when it is undeclared: a relay
opened 13 of them a robot, and with robots joining and leaving one a second, as many thread
starts. :func:`bridge_server.zenoh.inbox.direct` declares them on Zenoh's thread instead.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Iterator

import pytest
import zenoh

from bridge_server.zenoh.inbox import direct
from tests.relay.support import lone_session


def _threads() -> int:
    return len(os.listdir("/proc/self/task"))


@pytest.fixture
def session() -> Iterator[zenoh.Session]:
    with lone_session() as s:
        yield s


def test_direct_callbacks_start_no_thread_per_subscriber(session: zenoh.Session) -> None:
    """Ten subscribers and a liveliness subscriber declared through ``direct`` add no OS
    thread to the process (a plain callable adds one each)."""
    before = _threads()
    entities = [session.declare_subscriber(f"churn/{i}", direct(lambda _s: None))
                for i in range(10)]
    entities.append(session.liveliness().declare_subscriber("churn/**",
                                                            direct(lambda _s: None)))
    assert _threads() - before < 3, "a thread per subscriber"
    for e in entities:
        e.undeclare()  # type: ignore[no-untyped-call]


def test_direct_query_calls_back_and_ends(session: zenoh.Session) -> None:
    """A query's callback and its end given to ``direct`` are both called, the end after
    (fails with ``direct`` dropping ``end``)."""
    got: list[str] = []
    ended = threading.Event()
    queryable = session.declare_queryable(
        "churn/q", direct(lambda q: q.reply("churn/q", b"hi")))
    session.get("churn/q", direct(lambda r: got.append(r.ok.payload.to_string()), ended.set),
                timeout=5.0)
    assert ended.wait(10), "the query's end never came"
    assert got == ["hi"]
    queryable.undeclare()  # type: ignore[no-untyped-call]
