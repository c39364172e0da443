"""A robot's puts, off its event loop: the loop never waits for its link.

Zenoh answers a relay's recovery query (:mod:`.replay`) from a topic's cache on one of its
receive threads, and holds the cache while each reply waits for room on the link (replies
go with congestion control *block*); the topic's next put waits for the cache. Over a slow
or congested uplink that lasts as long as the replies take to cross it: a window of 300
messages of 3 KB asked for through a 2 KB/s link held the cache, and the put waiting for
it, for minutes. Put from the event loop, that stopped the robot's websocket clients, its
graph and its claims with it (``tests/relay/test_putter.py``).

So the exporter hands each message of a watched topic to :class:`Putter`, whose one thread
puts them in the order they came (a topic's messages keep their order, and a replay
publisher is closed after its last message). What waits for that thread is bounded
in bytes (:data:`PUT_QUEUE_BYTES`: a message that would take it over is dropped and
counted, :attr:`Putter.dropped`, as Zenoh drops a message that finds its link's queue full)
and in age (:data:`PUT_MAX_AGE`: a message that waited longer is dropped when its turn
comes, and counted the same way). Without the age bound, a thread held a long time puts
all it was given at once when let go: stale messages that the relays back first hear and
the others, back later, never do. (Some 500 messages 25 s stale that a restarted relay's
client heard in ``tests/relay/test_nat.py`` were first put down to this; they were the
robot's replay window, which a relay's new subscription asked for: :data:`.keys.PLACE`.)
A put that holds the thread over :data:`SLOW_PUT` s is logged.

A message given to the thread while it has nothing else to do lets go of Python's lock at
once (``time.sleep(0)``). Otherwise the woken thread waits for the lock until the loop, or
the robot's ROS thread, next lets go of it, which can take up to the interpreter's 5 ms
switch interval. A 100 Hz IMU's latency p50 through a relay (``python -m bench --scenario
relay_imu --quick``, three rounds each, on two busy cores) was 5.0-8.7 ms from the thread
without the yield and 4.2-5.3 ms with it, against 2.5-7.0 ms putting from the loop; on a
quiet machine 1.11-1.17 ms with it, against 1.05-1.35 ms from the loop.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections import deque
from collections.abc import Callable

__all__ = ["IDLE", "PUT_MAX_AGE", "PUT_QUEUE_BYTES", "Putter"]

log = logging.getLogger("bridge_server.zenoh.putter")

PUT_QUEUE_BYTES = 16 * 1024 * 1024
"""Payload bytes that may wait for a robot's putting thread: some seconds of everything a
robot streams, while a recovery's replies hold one of its topics."""

PUT_MAX_AGE = 10.0
"""Seconds a message may wait for the putting thread: one that waited longer is dropped
when its turn comes. Twice as long as Zenoh lets a put wait for room on a full link before
it closes the link (its ``wait_before_close``, 5 s): the messages behind a put that waits
for the link are put once the link is closed (into the replay window, for the relays when
they are back), and only a thread held by something else (a recovery's replies holding a
topic's window) drops them, stale by then."""

SLOW_PUT = 2.0
"""Seconds one put may hold the thread before the robot's log says so."""
SLOW_PUT_REPEAT = 30.0
"""Seconds between two such sayings."""

IDLE = 10.0
"""Seconds the putting thread waits with nothing to put before it ends (the next put starts
it again): a robot nobody watches any more, most of a fleet's simulated robots in one
process, keeps no thread."""


class Putter:
    """Runs a robot's puts on a daemon thread of its own, in the order they were given."""

    def __init__(self, limit: int = PUT_QUEUE_BYTES, idle: float = IDLE,
                 max_age: float = PUT_MAX_AGE,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.limit = limit
        self.idle = idle
        self.max_age = max_age
        self._clock = clock
        self._said_slow = -SLOW_PUT_REPEAT
        self.dropped = 0
        """Messages dropped: :attr:`limit` bytes were waiting already, or they waited longer
        than :attr:`max_age` s."""
        self._work: deque[tuple[Callable[[], None], int, float]] = deque()
        self._bytes = 0
        self._cond = threading.Condition()
        self._closed = False
        self._thread: threading.Thread | None = None
        """Started at a put, ended after :data:`IDLE` s with nothing to put."""

    @property
    def waiting(self) -> int:
        """Payload bytes given and not yet put."""
        return self._bytes

    @property
    def running(self) -> bool:
        """Whether the thread runs now (it ends after :data:`IDLE` s with nothing to put)."""
        return self._thread is not None

    def submit(self, work: Callable[[], None], size: int = 0) -> bool:
        """Run ``work`` on the thread after everything given before; ``size`` is the bytes
        it carries, counted against :attr:`limit` (0: never refused nor dropped, for a
        close). False, and ``work`` dropped, if the thread is closed or ``size`` more bytes
        would take what waits over the limit; a message given is still dropped if its turn
        comes more than :attr:`max_age` s later."""
        with self._cond:
            if self._closed:
                return False
            if size and self._bytes + size > self.limit:
                self._drop(f"{self._bytes} bytes wait to be put, a message of {size} bytes")
                return False
            idle = not self._work
            self._work.append((work, size, self._clock()))
            self._bytes += size
            self._cond.notify()
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="zenoh-put",
                                                daemon=True)
                self._thread.start()
        if idle:  # let the thread take Python's lock and put it now (see the module's text)
            time.sleep(0)
        return True

    def _run(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: bool(self._work) or self._closed, self.idle)
                if not self._work:  # closed, or idle: a put starts another
                    self._thread = None
                    return
                batch, self._work = self._work, deque()
            for work, size, given in batch:
                waited = self._clock() - given
                if size and waited > self.max_age:
                    with self._cond:
                        self._drop(f"a message of {size} bytes waited {waited:.1f} s")
                    continue
                began = self._clock()
                try:
                    work()
                except Exception:  # one put's failure (a closed session) must not end the rest
                    log.exception("a put to the robot's link failed")
                self._held(self._clock() - began)
            with self._cond:  # counted until put: what waits and what is being put
                self._bytes -= sum(size for _work, size, _given in batch)

    def _held(self, took: float) -> None:
        """Say so when one put held the thread over :data:`SLOW_PUT` s (at most once in
        :data:`SLOW_PUT_REPEAT` s): the robot's link, or a recovery answered from the
        topic's window, keeps the robot's messages waiting."""
        now = self._clock()
        if took > SLOW_PUT and now - self._said_slow > SLOW_PUT_REPEAT:
            self._said_slow = now
            log.warning("a put to the robot's link took %.1f s: the link is congested, or "
                        "a relay's recovery holds the topic's window", took)

    def _drop(self, why: str) -> None:
        """Count a dropped message, and say so at the first and each thousandth (the
        condition held)."""
        self.dropped += 1
        if self.dropped == 1 or self.dropped % 1000 == 0:
            log.warning("the robot's link takes less than it is given: %s is dropped "
                        "(%d so far)", why, self.dropped)

    def close(self, timeout: float = 5.0) -> bool:
        """Take nothing more, let the thread finish what it was given (at most
        ``timeout`` s) and end. Blocking: the loop runs it in an executor. False if the
        thread was still busy at the deadline (what it holds is left to it)."""
        with self._cond:
            self._closed = True
            self._cond.notify()
            thread = self._thread
        if thread is None:
            return True
        with contextlib.suppress(RuntimeError):
            thread.join(timeout)
        return not thread.is_alive()
