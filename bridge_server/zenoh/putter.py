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
(:data:`PUT_QUEUE_BYTES`): a message that would take it over is dropped and counted
(:attr:`Putter.dropped`), as Zenoh drops a message that finds its link's queue full.

A message given to the thread while it has nothing else to do lets go of Python's lock at
once (``time.sleep(0)``). Otherwise the woken thread waits for the lock until the loop, or
the robot's ROS thread, next lets go of it, which can take up to the interpreter's 5 ms
switch interval. A 100 Hz IMU's latency p50 through a relay (``python -m bench --scenario
relay_imu --quick``, three rounds each, on two busy cores) was 5.0-8.7 ms from the thread
without the yield and 4.2-5.3 ms with it, against 2.5-7.0 ms putting from the loop.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections import deque
from collections.abc import Callable

__all__ = ["IDLE", "PUT_QUEUE_BYTES", "Putter"]

log = logging.getLogger("bridge_server.zenoh.putter")

PUT_QUEUE_BYTES = 16 * 1024 * 1024
"""Payload bytes that may wait for a robot's putting thread: some seconds of everything a
robot streams, while a recovery's replies hold one of its topics."""

IDLE = 10.0
"""Seconds the putting thread waits with nothing to put before it ends (the next put starts
it again): a robot nobody watches any more, most of a fleet's simulated robots in one
process, keeps no thread."""


class Putter:
    """Runs a robot's puts on a daemon thread of its own, in the order they were given."""

    def __init__(self, limit: int = PUT_QUEUE_BYTES, idle: float = IDLE) -> None:
        self.limit = limit
        self.idle = idle
        self.dropped = 0
        """Messages dropped because :attr:`limit` bytes were waiting already."""
        self._work: deque[tuple[Callable[[], None], int]] = deque()
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
        it carries, counted against :attr:`limit` (0: never refused, for a close). False,
        and ``work`` dropped, if the thread is closed or ``size`` more bytes would take
        what waits over the limit."""
        with self._cond:
            if self._closed:
                return False
            if size and self._bytes + size > self.limit:
                self.dropped += 1
                if self.dropped == 1 or self.dropped % 1000 == 0:
                    log.warning("the robot's link takes less than it is given: %d bytes wait "
                                "to be put, a message of %d bytes is dropped (%d so far)",
                                self._bytes, size, self.dropped)
                return False
            idle = not self._work
            self._work.append((work, size))
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
            for work, _size in batch:
                try:
                    work()
                except Exception:  # one put's failure (a closed session) must not end the rest
                    log.exception("a put to the robot's link failed")
            with self._cond:  # counted until put: what waits and what is being put
                self._bytes -= sum(size for _work, size in batch)

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
