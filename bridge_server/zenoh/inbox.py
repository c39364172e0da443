"""What one robot's Zenoh callbacks hand to a relay's event loop, bounded per robot.

Zenoh calls the relay back on its own threads; every robot of a relay shares one event loop.
A :class:`Inbox` per robot stands between them, so that no robot can starve another:

- **topic messages** (and latched replies) wait in a queue of at most ``SAMPLE_LIMIT``
  messages and ``SAMPLE_BYTES`` bytes; a robot that sends faster than the loop handles
  loses its oldest ones (latest-only data: a viewer wants the newest), counted; one message
  over :data:`MESSAGE_BYTES` (the relay's ``--max-robot-message-bytes``) is dropped on
  Zenoh's thread, never queued, counted and logged with its key;
- **the graph document** waits in one slot: a newer one replaces the one not handled yet;
  one over ``GRAPH_BYTES`` is dropped on Zenoh's thread, never queued;
- **everything else** (query replies, goal events, the robot's queries to the relay,
  liveliness) is reliable: it waits in a queue of at most ``RELIABLE_LIMIT`` items and
  ``RELIABLE_BYTES`` bytes in order; past that a new item is dropped, counted, and the
  robot's clients are told (:attr:`Inbox.told`). A query's end is never dropped (one per
  query the relay asked) and comes after the query's replies.

The loop takes at most ``BATCH`` items of one robot at a time, then lets the other robots'
inboxes and the websockets run: a flooding robot gets its turn, not the loop.

What a robot sent that had to be dropped is counted by kind in :class:`Faults` and logged
once per kind (and again each time the count grows a hundredfold), never per message or
per viewer; the relay's page and ``/metrics`` show the counts.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
from collections import deque
from collections.abc import Callable
from typing import Any

import zenoh

__all__ = ["BATCH", "GRAPH_BYTES", "MESSAGE_BYTES", "RELIABLE_BYTES", "RELIABLE_LIMIT",
           "SAMPLE_BYTES", "SAMPLE_LIMIT", "Faults", "Inbox", "direct", "set_message_bytes"]

log = logging.getLogger("bridge_server.zenoh.graph")

SAMPLE_LIMIT = 1024
"""Topic messages of one robot waiting for the loop at most (the oldest go first)."""

SAMPLE_BYTES = 64 * 1024 * 1024
"""Payload bytes of one robot's topic messages waiting for the loop at most."""

MESSAGE_BYTES = 32 * 1024 * 1024
"""The largest message (topic message, or a reply or request) of a robot the relay takes by
default: a 4K rgb8 camera frame is 24.9 MB. The relay's ``--max-robot-message-bytes``."""

_message_bytes = MESSAGE_BYTES


def set_message_bytes(limit: int) -> None:
    """The largest message of the inboxes made from now on (the relay's option)."""
    global _message_bytes
    if limit < 1:
        raise ValueError(f"--max-robot-message-bytes {limit}: expected 1 or more")
    _message_bytes = limit


RELIABLE_LIMIT = 4096
"""Replies, queries and liveliness changes of one robot waiting for the loop at most."""

RELIABLE_BYTES = 16 * 1024 * 1024
"""Payload bytes of those at most."""

GRAPH_BYTES = 4 * 1024 * 1024
"""The largest graph document (``@graph``) of a robot the relay reads."""

BATCH = 64
"""Items of one robot handled in one turn of the loop."""

Handler = Callable[[Any], None]


def direct(fn: Handler, end: Callable[[], None] | None = None) -> zenoh.handlers.Callback[Any]:
    """``fn`` (and a query's ``end``) called on Zenoh's own thread: for callbacks that only
    hand to the loop (an :class:`Inbox`'s). A plain Python callable's default is a new Python
    thread per subscriber, queryable or query, started and ended with each (issue 49: ten
    a robot the relay opened; with the robot side's liveliness too, 1,760 threads in a
    process of 250 simulated robots, which then took over 10 minutes to join).

    Zenoh calls some of these (liveliness tokens, their queries' replies, transport events)
    holding its session's lock, and they wait there for the interpreter's lock. That is safe
    because no Python thread holds the interpreter's lock while it waits for one of Zenoh's:
    zenoh-python lets go of it around every call that may wait, and the one that did not, an
    advanced publisher's or subscriber's ``undeclare()`` (it drops their caches and heartbeat
    parts first), is never called: :func:`.replay.undeclare_aside` drops them instead. (With
    it, a 250-robot simulator process stopped for good: gdb showed ``close_queryable``
    waiting for the session's lock, Zenoh's receive threads in ``send_declare`` waiting for
    the interpreter's.)"""
    if end is None:
        return zenoh.handlers.Callback(fn, indirect=False)
    return zenoh.handlers.Callback(fn, end, indirect=False)


class Faults:
    """What one robot sent that the relay dropped or could not use, counted by kind; each
    kind logged the first time and again each time its count grows a hundredfold."""

    def __init__(self, robot: str) -> None:
        self.robot = robot
        self.counts: dict[str, int] = {}
        self.last: dict[str, str] = {}
        """What happened the last time, by kind."""
        self._lock = threading.Lock()  # counted on Zenoh's threads and on the loop

    def add(self, kind: str, why: str, n: int = 1, exc: BaseException | None = None) -> None:
        """``n`` more of ``kind`` (``why`` says what happened, naming no viewer)."""
        with self._lock:
            before = self.counts.get(kind, 0)
            now = self.counts[kind] = before + n
            self.last[kind] = why
        if before == 0 or _hundreds(now) > _hundreds(before):
            log.warning("robot %s: %s (%s: %d so far; counted on the relay's page, not logged "
                        "each time)", self.robot, why, kind, now,
                        exc_info=exc if before == 0 else None)


def _hundreds(n: int) -> int:
    """How many times ``n`` reaches a hundredfold (1 -> 0, 100 -> 1, 10000 -> 2)."""
    k = 0
    while n >= 100:
        n //= 100
        k += 1
    return k


class _Lane:
    """A bounded queue of (handler, argument, size)."""

    __slots__ = ("bytes", "items", "limit", "limit_bytes")

    def __init__(self, limit: int, limit_bytes: int) -> None:
        self.items: deque[tuple[Handler, Any, int]] = deque()
        self.bytes = 0
        self.limit = limit
        self.limit_bytes = limit_bytes

    def full_with(self, size: int) -> bool:
        return len(self.items) >= self.limit or self.bytes + size > self.limit_bytes

    def pop(self) -> tuple[Handler, Any, int]:
        item = self.items.popleft()
        self.bytes -= item[2]
        return item


class Inbox:
    """One robot's crossing from Zenoh's threads to the event loop (see the module text)."""

    def __init__(self, loop: asyncio.AbstractEventLoop, robot: str,
                 max_message: int | None = None) -> None:
        self.loop = loop
        self.max_message = _message_bytes if max_message is None else max_message
        """The largest payload taken, in bytes (a larger one is dropped, counted)."""
        self.faults = Faults(robot)
        self.told: list[Callable[[str], None]] = []
        """Called on the loop with a warning for the robot's clients (reliable data lost)."""
        self._samples = _Lane(SAMPLE_LIMIT, SAMPLE_BYTES)
        self._reliable = _Lane(RELIABLE_LIMIT, RELIABLE_BYTES)
        self._graph: tuple[Handler, Any] | None = None
        self._lock = threading.Lock()
        self._scheduled = False
        self._lost = 0  # reliable items dropped and not told yet

    # -- Zenoh's threads -------------------------------------------------------------------------

    def sample(self, fn: Handler) -> Handler:
        """A Zenoh callback of topic data: queued for ``fn``, the oldest dropped past the
        bound."""
        def cross(sample: Any) -> None:
            size = _size(sample)
            if size > self.max_message:
                self._too_large(sample, size)
                return
            dropped = 0
            lane = self._samples
            with self._lock:
                while lane.items and lane.full_with(size):
                    lane.pop()
                    dropped += 1
                lane.items.append((fn, sample, size))
                lane.bytes += size
                wake = self._schedule()
            if dropped:
                self.faults.add("messages_dropped", "topic messages dropped, the oldest "
                                "first: it sends faster than this relay handles (at most "
                                f"{SAMPLE_LIMIT} wait)", dropped)
            if wake:
                self._wake()

        return cross

    def reliable(self, fn: Handler) -> Handler:
        """A Zenoh callback of data that must not be lost silently: queued for ``fn`` in
        order; past the bound dropped, counted, and the robot's clients told."""
        def cross(arg: Any) -> None:
            size = _size(arg)
            if size > self.max_message:
                self._too_large(arg, size)
                with self._lock:
                    self._lost += 1
                    wake = self._schedule()
                if wake:
                    self._wake()
                return
            lane = self._reliable
            with self._lock:
                kept = not lane.full_with(size)
                if kept:
                    lane.items.append((fn, arg, size))
                    lane.bytes += size
                else:
                    self._lost += 1
                wake = self._schedule()
            if not kept:
                self.faults.add("replies_dropped", "replies or requests dropped: it sends "
                                f"more than this relay handles (at most {RELIABLE_LIMIT} wait)")
            if wake:
                self._wake()

        return cross

    def graph(self, fn: Handler) -> Handler:
        """A Zenoh callback of graph documents: one waits (the newest); one over
        ``GRAPH_BYTES`` is dropped here."""
        def cross(sample: Any) -> None:
            size = _size(sample)
            if size > GRAPH_BYTES:
                self.faults.add("graph_too_large", f"a graph document of {size} bytes, over "
                                f"the limit of {GRAPH_BYTES}, dropped")
                return
            with self._lock:
                replaced = self._graph is not None
                self._graph = (fn, sample)
                wake = self._schedule()
            if replaced:
                self.faults.add("graph_superseded", "graph documents replaced by a newer one "
                                "before this relay read them")
            if wake:
                self._wake()

        return cross

    def end(self, fn: Callable[[], None]) -> Callable[[], None]:
        """A query's end (one per query the relay asked): after the query's replies, in the
        same queue, and never dropped."""
        def cross() -> None:
            with self._lock:
                self._reliable.items.append((lambda _: fn(), None, 0))
                wake = self._schedule()
            if wake:
                self._wake()

        return cross

    def _too_large(self, arg: Any, size: int) -> None:
        """(Zenoh's thread.) A payload over :attr:`max_message`: counted and logged with its
        key, never queued."""
        where = getattr(arg, "key_expr", None) or getattr(getattr(arg, "ok", None), "key_expr",
                                                          "(a reply)")
        self.faults.add("message_too_large", f"a message of {size} bytes on {where}, over "
                        f"the limit of {self.max_message} bytes a message "
                        "(--max-robot-message-bytes), dropped")

    def _schedule(self) -> bool:
        """(Under the lock.) A drain will run: whether the loop must be woken for it."""
        wake = not self._scheduled
        self._scheduled = True
        return wake

    def _wake(self) -> None:
        with contextlib.suppress(RuntimeError):  # the loop closed meanwhile
            self.loop.call_soon_threadsafe(self._drain)

    # -- the loop --------------------------------------------------------------------------------

    def _drain(self) -> None:
        """Handle up to ``BATCH`` items (reliable ones, the graph, then topic messages), then
        come back after the loop's other work if more wait."""
        with self._lock:
            batch: list[tuple[Handler, Any]] = []
            for lane in (self._reliable, self._samples):
                while lane.items and len(batch) < BATCH:
                    fn, arg, _ = lane.pop()
                    batch.append((fn, arg))
            if self._graph is not None and len(batch) < BATCH:
                batch.append(self._graph)
                self._graph = None
            lost, self._lost = self._lost, 0
            more = bool(self._reliable.items or self._samples.items or self._graph)
            self._scheduled = more
        for fn, arg in batch:
            try:
                fn(arg)
            except Exception as exc:  # one robot's bad data must not stop the others
                self.faults.add("handling_failed", f"handling what it sent failed "
                                f"({type(exc).__name__})", exc=exc)
        if lost:
            for tell in list(self.told):
                tell(f"robot {self.faults.robot}: {lost} replies or requests from it were "
                     "dropped (it sends more than this relay handles); a call or goal may "
                     "fail for it")
        if more:
            self.loop.call_soon(self._drain)

    def waiting(self) -> dict[str, int]:
        """What waits now (for the relay's page)."""
        with self._lock:
            return {"messages": len(self._samples.items), "message_bytes": self._samples.bytes,
                    "reliable": len(self._reliable.items)}


def _size(arg: Any) -> int:
    """The payload bytes of a sample, reply or query (0 for what has none)."""
    payload = getattr(arg, "payload", None)
    if payload is None:
        ok = getattr(arg, "ok", None)
        payload = getattr(ok, "payload", None) if ok is not None else None
    return len(payload) if payload is not None else 0
