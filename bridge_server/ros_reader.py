"""The topic reader: the bridge's shared subscriptions, waited on by a thread of their own.

rclpy's executor hands out one ready entity at a time, and before each it rebuilds its
wait set in Python from every entity of the node (the service clients and the action
clients and servers that sessions use), then runs the callback as a task. On the
bridge that was most of a message's time from the ROS publisher to the client: at
200 Hz the executor took 0.37 ms (median) to reach the callback of a message that an
rclpy subscriber in another process had in 0.22 ms, and the loop thread then waited
for the GIL while the executor rebuilt its wait set again.

The topics are therefore not the executor's: :class:`TopicReader` creates their rcl
subscriptions on the bridge's node without registering them with rclpy's
:class:`~rclpy.node.Node` (so the executor never waits on them) and waits on them, and
on a guard condition that tells it the set changed, in a thread that does nothing else.
Its wait set is made again only when the topics change; what it takes crosses to the
loop in one hand-off per round, made just before it waits again.

This uses rclpy's implementation module (``_rclpy``) directly, as rclpy's own executor
does: ``Subscription``, ``WaitSet`` and ``GuardCondition`` of the pinned Jazzy release.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from rclpy.exceptions import InvalidHandle
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.type_support import check_is_valid_msg_type

__all__ = ["FailureLog", "ReaderSubscription", "TopicReader"]

log = logging.getLogger("bridge_server.ros")

ERROR_LOG_INTERVAL = 10.0
"""Seconds between two logged failures of a reader or executor round (the others counted)."""


class FailureLog:
    """Logs a recurring failure (with its traceback) at most once per ``interval`` seconds,
    saying how many more there were since the last report; ``count`` counts them all."""

    def __init__(self, what: str, interval: float = ERROR_LOG_INTERVAL) -> None:
        self.what = what
        self.interval = interval
        self.count = 0
        self._last = -interval
        self._quiet = 0

    def failed(self, what: str | None = None) -> None:
        """Call in an ``except`` block (``what``: this failure's own words, if not the usual)."""
        self.count += 1
        now = time.monotonic()
        if now - self._last < self.interval:
            self._quiet += 1
            return
        self._last = now
        more = f" ({self._quiet} more since the last report)" if self._quiet else ""
        self._quiet = 0
        log.exception("%s%s", what or self.what, more)


class ReaderSubscription:
    """One rcl subscription waited on by a :class:`TopicReader`.

    ``take(handle)`` is called on the reader's thread whenever the subscription has
    messages; it takes them with ``handle.take_message`` and returns those to hand on (the
    handle is held for it). The reader then has ``deliver(messages, stamp_ns)`` run on the
    loop, with the time they were taken (``time.time_ns()``).
    """

    __slots__ = ("deliver", "handle", "take", "topic")

    def __init__(
        self,
        handle: Any,
        topic: str,
        take: Callable[[Any], list[bytes]],
        deliver: Callable[[list[bytes], int], None],
    ) -> None:
        self.handle = handle
        self.topic = topic
        self.take = take
        self.deliver = deliver


class TopicReader:
    """A thread that waits on the bridge's topic subscriptions and nothing else.

    ``post(fn, *args)`` runs ``fn(*args)`` on the loop (:meth:`RosNode.post`).
    """

    def __init__(self, context: Any, node: Any, post: Callable[..., None]) -> None:
        self.context = context
        self.node = node
        self.post = post
        self._subs: tuple[ReaderSubscription, ...] = ()
        self._lock = threading.Lock()
        self._stopping = False
        self._thread: threading.Thread | None = None
        with context.handle:
            self._wake = _rclpy.GuardCondition(context.handle)
        self.errors = FailureLog("ROS topic reader round failed; reading on")
        """Reader rounds or takes that raised (``errors.count``)."""

    def start(self) -> None:
        """Start the reader's thread."""
        self._thread = threading.Thread(target=self._run, name="bridge-ros-topics", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the thread and destroy every subscription (before the node is destroyed)."""
        self._stopping = True
        with contextlib.suppress(Exception):
            self._wake.trigger_guard_condition()
        if self._thread is not None:
            self._thread.join(2.0)
        with self._lock:
            subs, self._subs = self._subs, ()
        for sub in subs:
            with contextlib.suppress(Exception):
                sub.handle.destroy_when_not_in_use()
        with contextlib.suppress(Exception):
            self._wake.destroy_when_not_in_use()

    def subscribe(
        self,
        msg_cls: type[Any],
        topic: str,
        qos: Any,
        take: Callable[[Any], list[bytes]],
        deliver: Callable[[list[bytes], int], None],
    ) -> ReaderSubscription:
        """Create a subscription on the node and wait on it (see :class:`ReaderSubscription`)."""
        check_is_valid_msg_type(msg_cls)  # type: ignore[no-untyped-call]  # loads type support
        with self.node.handle:
            handle = _rclpy.Subscription(
                self.node.handle, msg_cls, topic, qos.get_c_qos_profile()
            )
        sub = ReaderSubscription(handle, topic, take, deliver)
        with self._lock:
            self._subs = (*self._subs, sub)
        self._wake.trigger_guard_condition()
        return sub

    def unsubscribe(self, sub: ReaderSubscription) -> None:
        """Stop waiting on ``sub`` and destroy it (once the reader no longer holds it)."""
        with self._lock:
            self._subs = tuple(s for s in self._subs if s is not sub)
        with contextlib.suppress(Exception):
            self._wake.trigger_guard_condition()
        with contextlib.suppress(InvalidHandle):
            sub.handle.destroy_when_not_in_use()

    def _run(self) -> None:
        """Wait and take until stopped.

        The wait set is made anew only when the subscriptions change; the reader holds
        each subscription's handle while it is in the set (so a destroy waits for it), and
        lets go of it when it leaves. What a round took is handed to the loop just before
        the next wait, so the thread does not hold the GIL when the loop wakes for it.
        """
        held: dict[int, ReaderSubscription] = {}  # id -> subscription whose handle we hold
        subs: tuple[ReaderSubscription, ...] = ()
        live: list[ReaderSubscription] = []
        wait_set: Any = None
        taken: list[tuple[ReaderSubscription, list[bytes]]] = []
        try:
            with self.context.handle, self._wake:
                while not self._stopping:
                    try:
                        if self._subs is not subs or wait_set is None:
                            subs = self._subs
                            live = self._hold(subs, held)
                            wait_set = _rclpy.WaitSet(
                                len(live), 1, 0, 0, 0, 0, self.context.handle
                            )
                        wait_set.clear_entities()
                        for sub in live:
                            wait_set.add_subscription(sub.handle)
                        wait_set.add_guard_condition(self._wake)
                        if taken:
                            stamp = time.time_ns()
                            for sub, batch in taken:
                                self.post(sub.deliver, batch, stamp)
                            taken = []
                        wait_set.wait(-1)
                        if self._stopping:
                            break
                        ready = wait_set.get_ready_entities("subscription")
                        if ready:
                            for sub in live:
                                if sub.handle.pointer in ready:
                                    try:
                                        batch = sub.take(sub.handle)
                                    except Exception:  # the others are still served
                                        self.errors.failed(
                                            f"taking messages of {sub.topic} failed")
                                        continue
                                    if batch:
                                        taken.append((sub, batch))
                    except Exception:
                        if self._stopping or not self.context.ok():
                            break
                        wait_set = None  # made anew next round
                        self.errors.failed()
        finally:
            self._hold((), held)

    @staticmethod
    def _hold(
        subs: tuple[ReaderSubscription, ...], held: dict[int, ReaderSubscription]
    ) -> list[ReaderSubscription]:
        """Hold the handles of ``subs`` (let go of the others); returns those held."""
        wanted = {id(s) for s in subs}
        for key in [k for k in held if k not in wanted]:
            with contextlib.suppress(Exception):  # a destroy waiting for it happens now
                held.pop(key).handle.__exit__(None, None, None)
        for sub in subs:
            if id(sub) not in held:
                try:
                    sub.handle.__enter__()
                except InvalidHandle:  # destroyed since it was listed
                    continue
                held[id(sub)] = sub
        return [s for s in subs if id(s) in held]
