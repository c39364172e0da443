"""Nothing lost in a robot-link outage, within a bounded window: Zenoh's own machinery.

A robot's link to its relays may drop (a tunnel, a dead Wi-Fi cell) for longer than the
lease; meanwhile its reliable topics keep being published in ROS. The exporter puts each
message of a **reliable** topic through a ``zenoh.ext`` advanced publisher
(:class:`ReplayPublisher`) with a cache of its last messages and sample-miss detection
(sequence numbers, and a heartbeat each period so a topic that fell silent during the outage
is caught up too). The relay takes every topic through an advanced subscriber with
recovery (:func:`recovering_subscriber`): when the link is back, the first message after
the gap (or the heartbeat) shows the gap, the subscriber asks the robot's cache for what
it missed and hands everything on once and in order; what the cache no longer holds is
reported by its miss listener with the count, and the relay tells the robot's clients.

The window is per topic: at most ``count`` messages and ``bytes`` payload bytes
(:class:`ReplayWindow`, the robot's ``--relay-replay-count`` and ``--relay-replay-bytes``);
its memory is in the robot's ``/metrics``. Best-effort and latched (transient local) topics
are put plainly: latest wins, nothing is replayed. So is a topic once one of its messages is
larger than :data:`REPLAY_MAX_MESSAGE_BYTES` (a camera, a point cloud): see there why.

While its link is down the robot cannot hear that a relay stopped watching (its demand
tokens vanish with the link): a replayed topic is kept subscribed, and caching, until the
link has been back :data:`DEMAND_LINGER` seconds without a relay asking for it again.
"""

from __future__ import annotations

import logging
import queue
import threading
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from bridge_server.zenoh.priority import MEDIUM_MESSAGE, TopicPriority

if TYPE_CHECKING:  # zenoh is imported when used: the bridge's options parse without it
    import zenoh
    from prometheus_client.core import Metric

__all__ = ["DEFAULT_REPLAY_BYTES", "DEFAULT_REPLAY_COUNT", "DEFAULT_REPLAY_TOTAL_BYTES",
           "DEMAND_LINGER", "HEARTBEAT", "REPLAY_MAX_MESSAGE_BYTES", "SETTLE_WAIT",
           "ReplayBudget", "ReplayPublisher", "ReplayWindow", "recovering_subscriber",
           "settle_aside", "undeclare_aside", "window_metrics"]

log = logging.getLogger("bridge_server.zenoh.replay")

DEFAULT_REPLAY_COUNT = 300
"""Messages of one reliable topic the robot keeps for its relays (30 s of a 10 Hz topic)."""

DEFAULT_REPLAY_BYTES = 8 * 1024 * 1024
"""Payload bytes of one reliable topic the robot keeps for its relays at most."""

DEFAULT_REPLAY_TOTAL_BYTES = 64 * 1024 * 1024
"""Payload bytes the robot keeps for its relays at most, all reliable topics together (the
relays' clients choose how many topics are watched)."""

HEARTBEAT = 1.0
"""Seconds between two heartbeats of a replayed topic (the relay learns of messages it missed
at the end of a burst, with nothing after them). Sent each period whether or not the topic
published since the last one: Zenoh's sporadic heartbeat (only after a publish) is spent
into the void when the topic's last message and the heartbeat after it fall in an outage,
and the relay then never learns of that message. It costs a few bytes a second per watched
topic, and nothing while no relay subscribes (Zenoh drops a put nobody matches)."""

REPLAY_MAX_MESSAGE_BYTES = MEDIUM_MESSAGE
"""The largest message of a topic that is replayed; a topic with a larger one is put plainly
from then on (latest wins), as a best-effort topic is. The heartbeat tells the relay the
last number the robot sent while a big frame is still on its way (on a slow link, while the
relay is busy), so the relay asks the robot's cache for it and it crosses the link twice:
with replay a 10 Hz 640x480 camera cost the robot's uplink 2.0 times one viewer's at 10
viewers and 2.7 at 50 (``python -m bench --scenario relay_uplink``), against 1.0 put
plainly, on the very links relays are for. A small message is on its way for far less than
the heartbeat's period, and a replayed frame would be stale video anyway."""

DEMAND_LINGER = 5.0
"""Seconds a replayed topic that no relay watches any more stays subscribed once the
robot's link is up (the relays' demand comes back within a second or two of the link)."""


@dataclass(frozen=True)
class ReplayWindow:
    """How much of each reliable topic the robot keeps for relays that lost their link:
    ``count`` messages and ``bytes`` payload bytes at most (``count`` 0: none, every topic
    is put plainly), and ``total`` bytes all topics together."""

    count: int = DEFAULT_REPLAY_COUNT
    bytes: int = DEFAULT_REPLAY_BYTES
    total: int = DEFAULT_REPLAY_TOTAL_BYTES

    def __post_init__(self) -> None:
        if self.count < 0:
            raise ValueError(f"--relay-replay-count {self.count}: expected 0 or more messages")
        for option, value in (("--relay-replay-bytes", self.bytes),
                              ("--relay-replay-total-bytes", self.total)):
            if value < 1:
                raise ValueError(f"{option} {value}: expected 1 or more bytes")

    def depth(self, largest: int) -> int:
        """How many messages of at most ``largest`` bytes fit (at least one)."""
        return max(1, min(self.count, self.bytes // max(largest, 1)))


class ReplayBudget:
    """The bytes all of a robot's replay windows may reserve together (``total``): a
    window reserves its depth times the largest message it has seen."""

    def __init__(self, total: int) -> None:
        self.total = total
        self.reserved = 0


class ReplayPublisher:
    """One reliable topic's advanced publisher on the robot, with a cache of its last
    messages (see the module's text).

    Zenoh's cache counts messages, not bytes: its depth is what fits the byte cap at the
    size of the largest message seen (:meth:`ReplayWindow.depth`), and what is left of the
    robot's ``budget``. A message larger than any before that would take the cache over
    either makes a new, shallower cache (what the old one held is dropped then, logged);
    with no room left for one message, or a message over :data:`REPLAY_MAX_MESSAGE_BYTES`,
    the topic is put plainly from then on (logged).
    :attr:`held` and :attr:`held_bytes` mirror what the cache holds."""

    def __init__(self, session: zenoh.Session, key: str, window: ReplayWindow,
                 topic: str, budget: ReplayBudget) -> None:
        self.session = session
        self.key = key
        self.window = window
        self.topic = topic
        self.budget = budget
        self._reserved = 0
        self.plain = False
        """No room in the budget, or a message too large: the topic is put plainly (not
        replayed)."""
        self.largest = 0
        self.resized = 0
        """How many times a larger message made a shallower cache."""
        self._sizes: deque[int] = deque()
        self._held_bytes = 0
        self._pub: Any = None
        self.qos = TopicPriority()
        """The topic's priority on the link (:mod:`.priority`), that of its publisher."""

    @property
    def held(self) -> int:
        """Messages the cache holds now."""
        return len(self._sizes)

    @property
    def held_bytes(self) -> int:
        """Payload bytes the cache holds now."""
        return self._held_bytes

    def _declare(self, depth: int) -> None:
        import zenoh.ext

        if self._pub is not None:
            gone, self._pub = [self._pub], None
            undeclare_aside(gone)
        self._sizes = deque(maxlen=depth)
        self._held_bytes = 0
        self._pub = zenoh.ext.declare_advanced_publisher(
            self.session, self.key, reliability=zenoh.Reliability.RELIABLE,
            cache=zenoh.ext.CacheConfig(depth), **self.qos.kwargs,
            sample_miss_detection=zenoh.ext.MissDetectionConfig(
                heartbeat=HEARTBEAT, sporadic_heartbeat=None),
            publisher_detection=True)

    def _reserve(self, size: int) -> int:
        """The depth for messages of ``size`` bytes within the window, the cache's depth
        now (a cache only shrinks) and what the budget has left (0: not one), reserved."""
        budget = self.budget
        free = budget.total - budget.reserved + self._reserved
        depth = min(self.window.depth(size), free // max(size, 1))
        if self._pub is not None:
            depth = min(depth, self._sizes.maxlen or 0)
        budget.reserved += depth * size - self._reserved
        self._reserved = depth * size
        return depth

    def put(self, payload: bytes, attachment: bytes, qos: TopicPriority | None = None
            ) -> None:
        """Publish one message (kept in the cache, the oldest going past the window) at
        priority ``qos`` (the topic's; a change makes a new publisher, the cache dropped)."""
        size = len(payload)
        if qos is not None and qos != self.qos:
            self.qos = qos
            if self._pub is not None:
                self._declare(self._sizes.maxlen or 1)
        if size > self.largest and not self.plain:
            self.largest = size
            if size > REPLAY_MAX_MESSAGE_BYTES:
                self.close()
                self.plain = True
                log.info("%s: a message of %d bytes, over %d: put plainly from now on (latest "
                         "wins), not replayed", self.topic, size, REPLAY_MAX_MESSAGE_BYTES)
                self.session.put(self.key, payload, attachment=attachment, **self.qos.kwargs)
                return
            depth = self._reserve(size)
            if depth == 0:
                self.close()
                self.plain = True
                log.warning("%s: no room for its replay window (--relay-replay-total-bytes %d "
                            "reserved by other topics): put plainly, not replayed",
                            self.topic, self.budget.total)
            elif self._pub is None or depth < (self._sizes.maxlen or 0):
                if self._sizes:
                    self.resized += 1
                    log.warning("%s: a message of %d bytes makes its replay window %d "
                                "messages (--relay-replay-bytes %d, --relay-replay-total-bytes "
                                "%d); the %d it held are dropped", self.topic, size, depth,
                                self.window.bytes, self.budget.total, len(self._sizes))
                self._declare(depth)
        if self.plain:
            self.session.put(self.key, payload, attachment=attachment, **self.qos.kwargs)
            return
        sizes = self._sizes
        if len(sizes) == sizes.maxlen:
            self._held_bytes -= sizes[0]
        sizes.append(size)
        self._held_bytes += size
        self._pub.put(payload, attachment=attachment)

    def close(self) -> None:
        """Undeclare it (its cache goes; off the loop: :func:`undeclare_aside`)."""
        if self._pub is not None:
            gone, self._pub = [self._pub], None
            undeclare_aside(gone)
        self._sizes.clear()
        self._held_bytes = 0
        self.budget.reserved -= self._reserved
        self._reserved = 0


def recovering_subscriber(session: zenoh.Session, key: str, on_sample: Callable[[Any], None],
                          on_miss: Callable[[int], None]) -> list[Any]:
    """An advanced subscriber of ``key`` that asks a robot's cache for the messages it
    missed and hands every message to ``on_sample`` once and in order (a plain put too, as
    it comes); ``on_miss`` hears how many in a row the cache no longer had. Returns what to
    undeclare (the subscriber and its miss listener), with :func:`undeclare_aside`.

    Both are given their callbacks as ``(callback, None)``, not as a bare callable: Zenoh
    keeps an entity whose handler is a bare callable "in the background", and an advanced
    subscriber in the background leaves its heartbeat subscriber and its state (with
    ``on_sample``) behind when undeclared, for the session's life: some 1.7 KB, and a query
    to the robot's cache at its heartbeats, at each topic a relay stopped watching. The miss
    listener's ``on_miss`` runs on Zenoh's thread (:func:`.inbox.direct`): a bare callable
    would be a Python thread of its own for each."""
    import zenoh.ext

    from bridge_server.zenoh.inbox import direct

    sub = zenoh.ext.declare_advanced_subscriber(
        session, key, (on_sample, None),
        recovery=zenoh.ext.RecoveryConfig(periodic_queries=None, heartbeat=True))
    missed = sub.sample_miss_listener((direct(lambda miss: on_miss(int(miss.nb))), None))
    return [missed, sub]


_going: queue.SimpleQueue[list[Any] | threading.Event] | None = None
_going_lock = threading.Lock()

SETTLE_WAIT = 30.0
"""Seconds :func:`settle_aside` waits at most (an undeclaration may wait 10 s for its tasks)."""


def undeclare_aside(entities: list[Any]) -> None:
    """Undeclare ``entities`` (Zenoh entities; an advanced publisher or subscriber among
    them) in order on a thread of their own, not the caller's (the event loop); ``entities``
    is emptied, and the caller must hold no other reference to them. Before their session
    closes, :func:`settle_aside` (Zenoh may panic undeclaring an entity of a closed session).

    They are undeclared by dropping them there, not by their ``undeclare()``: an advanced
    entity's ``undeclare()`` drops its cache, its heartbeat and its liveliness parts holding
    the interpreter's lock, and those wait for the session's lock, which Zenoh's threads may
    hold while waiting for the interpreter's (a callback): a deadlock. Dropping them lets
    go of the interpreter's lock first. So an entity given here must not be in the
    background (declared with a bare callable as its handler: dropping would leave it
    declared); give its callback as ``(callback, None)``. And off the loop: the
    undeclaration waits for the entity's tasks to end, and Zenoh's threads that would end
    them may be waiting for the loop meanwhile (a callback handing a sample to it): 250
    simulated robots in one process, 5,000 viewers watching, stalled their loop 10 s at each
    topic a relay stopped watching (Zenoh's "Failed to terminate the task" each time), one
    after another, and answered nothing for minutes."""
    batch = entities.copy()
    entities.clear()
    _aside().put(batch)


def settle_aside(timeout: float = SETTLE_WAIT) -> bool:
    """Wait (blocking: on a thread of the executor) until what :func:`undeclare_aside` was
    given before is undeclared; whether it was within ``timeout`` s."""
    done = threading.Event()
    _aside().put(done)
    return done.wait(timeout)


def _aside() -> queue.SimpleQueue[list[Any] | threading.Event]:
    global _going
    with _going_lock:
        if _going is None:
            _going = queue.SimpleQueue()
            threading.Thread(target=_drop_each, args=(_going,), name="zenoh-undeclare",
                             daemon=True).start()
        return _going


def _drop_each(going: queue.SimpleQueue[list[Any] | threading.Event]) -> None:
    """The thread of :func:`undeclare_aside`: it pops each entity from its batch, so that
    its own is the last reference, and lets go of it."""
    while True:
        batch = going.get()
        if isinstance(batch, threading.Event):
            batch.set()
            continue
        while batch:
            entity = batch.pop(0)
            del entity  # the last reference: Zenoh undeclares it, the interpreter's lock free


def window_metrics(windows: Mapping[str, tuple[int, int]], may_see: Callable[[str], bool]
                   ) -> list[Metric]:
    """The robot's ``/metrics`` families of its replay windows (``windows``: messages and
    payload bytes held, by topic), the topics a viewer may not see left out."""
    from prometheus_client.core import GaugeMetricFamily

    held = GaugeMetricFamily(
        "roslibpy_bridge_relay_replay_messages",
        "Messages of a reliable topic the robot holds for relays whose link drops (its "
        "replay window, at most --relay-replay-count).", labels=["topic"])
    held_bytes = GaugeMetricFamily(
        "roslibpy_bridge_relay_replay_bytes",
        "Payload bytes of those messages (at most --relay-replay-bytes per topic).",
        labels=["topic"])
    for topic, (n, size) in sorted(windows.items()):
        if may_see(topic):
            held.add_metric([topic], n)
            held_bytes.add_metric([topic], size)
    return [held, held_bytes]
