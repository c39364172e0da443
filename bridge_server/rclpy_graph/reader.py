"""The topic readers: the bridge's shared subscriptions, taken outside rclpy's executor.

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

Where it can, the bridge does better than a thread: :class:`LoopReader` has the middleware
itself wake the event loop. rcl lets a subscription name a function that the middleware
calls, on its own thread, for every message that arrives
(``rcl_subscription_set_on_new_message_callback``, what rclpy's events executor is built
on). The function given is the C library's ``eventfd_write`` and the data pointer it gets
is an eventfd's number, which the loop waits on beside its sockets: a message wakes the
loop thread directly, which takes it. No Python runs on the middleware's thread (a
callback that took the GIL there could deadlock with a take on the loop), and a
message crosses one thread instead of two (each wake of a sleeping thread cost 30-50 µs
on a small VM). rmw calls the function under a lock that unsetting it takes too, so once
unset it is not running and the eventfd can be closed.

The callback's C type is ``void (*)(const void *user_data, size_t count)`` and
``eventfd_write``'s is ``int (*)(int fd, uint64_t value)``: on x86-64 and AArch64 (System
V and AAPCS64) both pass their two arguments in the first two integer registers, the
pointer's low 32 bits are the descriptor and ``count`` (the number of new messages, never
0) is what is added to the eventfd's counter. The return value is ignored. So it is used
only on Linux on those two machines, and with rmw_fastrtps (the default middleware, the one
tested); elsewhere, or when the symbols are missing, the reader thread serves.

The loop reader serves the services that clients advertise the same way
(``rcl_service_set_on_new_request_callback``): a ROS caller's request wakes the loop, which
takes it with its header and answers on the loop when the client has, where rclpy's
executor would have rebuilt its wait set, run the callback on its thread and handed the
request over (see :class:`ReaderService`).

This uses rclpy's implementation module (``_rclpy``) directly, as rclpy's own executor
does: ``Subscription``, ``WaitSet`` and ``GuardCondition`` of the pinned Jazzy release.
"""

from __future__ import annotations

import asyncio
import contextlib
import ctypes
import logging
import os
import platform
import sys
import threading
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import Any

from rclpy.exceptions import InvalidHandle
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.type_support import check_for_type_support, check_is_valid_msg_type
from rclpy.utilities import get_rmw_implementation_identifier

__all__ = [
    "MAX_BATCH",
    "READERS",
    "WAKING_RMW",
    "FailureLog",
    "LoopReader",
    "Reader",
    "ReaderService",
    "ReaderSubscription",
    "TopicReader",
    "open_reader",
]

log = logging.getLogger("bridge_server.rclpy_graph.node")

MAX_BATCH = 256
"""Most messages taken from one subscription at a time (the reader comes back for more)."""

Take = Callable[[Any, int], tuple[list[bytes], int]]
"""``take(handle, limit) -> (messages, taken)``: see :class:`ReaderSubscription`."""

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
    """One rcl subscription of a topic reader.

    ``take(handle, limit)`` is called whenever the subscription has messages (on the
    reader's thread, or on the loop for a :class:`LoopReader`); it takes up to ``limit``
    with ``handle.take_message`` (stopping early when none is left) and returns those to
    hand on and how many it took (a reader thread holds the handle meanwhile). The reader
    then has ``deliver(messages, stamp_ns)`` run on the loop, with the time they were
    taken (``time.time_ns()``).
    """

    __slots__ = ("deliver", "fd", "handle", "take", "topic")

    def __init__(
        self,
        handle: Any,
        topic: str,
        take: Take,
        deliver: Callable[[list[bytes], int], None],
    ) -> None:
        self.handle = handle
        self.topic = topic
        self.take = take
        self.deliver = deliver
        self.fd = -1  # a LoopReader's eventfd


class ReaderService:
    """One rcl service served on the loop (:meth:`LoopReader.serve`).

    ``on_request(request, header)`` runs on the loop for each request a ROS caller sends;
    :meth:`respond` answers it (on the loop, whenever the answer is there).
    """

    __slots__ = ("fd", "handle", "name", "on_request", "request_cls")

    def __init__(self, handle: Any, name: str, request_cls: type[Any],
                 on_request: Callable[[Any, Any], None]) -> None:
        self.handle = handle
        self.name = name
        self.request_cls = request_cls
        self.on_request = on_request
        self.fd = -1

    def respond(self, response: Any, header: Any) -> None:
        """Send ``response`` to the caller whose request came with ``header`` (its
        ``rmw_service_info_t``)."""
        self.handle.service_send_response(response, header.request_id)


class Reader(ABC):
    """What waits on the bridge's topic subscriptions: a :class:`LoopReader` or a
    :class:`TopicReader`."""

    kind = ""
    """``loop`` or ``thread``."""

    def __init__(self, node: Any, what_fails: str) -> None:
        self.node = node
        self.errors = FailureLog(what_fails)
        """Takes (or reader rounds) that raised (``errors.count``)."""

    def subscribe(
        self,
        msg_cls: type[Any],
        topic: str,
        qos: Any,
        take: Take,
        deliver: Callable[[list[bytes], int], None],
    ) -> ReaderSubscription:
        """Create a subscription on the node that rclpy's executor does not know of, and
        have its messages taken when they come (see :class:`ReaderSubscription`)."""
        check_is_valid_msg_type(msg_cls)  # type: ignore[no-untyped-call]  # loads type support
        with self.node.handle:
            handle = _rclpy.Subscription(self.node.handle, msg_cls, topic,
                                         qos.get_c_qos_profile())
        sub = ReaderSubscription(handle, topic, take, deliver)
        self._add(sub)
        return sub

    @abstractmethod
    def _add(self, sub: ReaderSubscription) -> None:
        """Start taking ``sub``'s messages."""

    @abstractmethod
    def unsubscribe(self, sub: ReaderSubscription) -> None:
        """Stop taking ``sub``'s messages and destroy it."""

    @abstractmethod
    def stop(self) -> None:
        """Destroy every subscription (before the node is destroyed)."""


READERS = ("auto", "thread")
"""What ``--topic-reader`` may ask for (see :func:`open_reader`)."""


def open_reader(context: Any, node: Any, loop: asyncio.AbstractEventLoop,
                post: Callable[..., None], kind: str = "auto") -> Reader:
    """``auto``: a :class:`LoopReader` where the middleware can wake the loop, else a
    started :class:`TopicReader`; ``thread``: the latter."""
    if kind not in READERS:
        raise ValueError(f"topic reader {kind!r}: expected one of {', '.join(READERS)}")
    wake = _eventfd_wake() if kind == "auto" else None
    if wake is not None:
        return LoopReader(node, loop, *wake)
    reader = TopicReader(context, node, post)
    reader.start()
    return reader


WAKING_RMW = "rmw_fastrtps_cpp"
"""The middleware the loop reader is used with: ROS 2's default, the one tested here."""


def _eventfd_wake() -> tuple[Any, Any, int] | None:
    """rcl's "on new message" and "on new request" setters and ``eventfd_write``'s address,
    where they work (see the module's docstring), with :data:`WAKING_RMW`."""
    if sys.platform != "linux" or platform.machine() not in ("x86_64", "aarch64"):
        return None
    if get_rmw_implementation_identifier() != WAKING_RMW:
        return None
    try:
        rcl = ctypes.CDLL("librcl.so", mode=os.RTLD_NOLOAD)  # the one rclpy loaded
        setter = rcl.rcl_subscription_set_on_new_message_callback
        service_setter = rcl.rcl_service_set_on_new_request_callback
        write = ctypes.cast(ctypes.CDLL(None).eventfd_write, ctypes.c_void_p).value
    except (OSError, AttributeError):
        return None
    if write is None:
        return None
    for fn in (setter, service_setter):
        fn.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
        fn.restype = ctypes.c_int
    return setter, service_setter, write


class LoopReader(Reader):
    """The topics taken on the loop thread, which the middleware wakes through an eventfd
    per subscription (see the module's docstring). Every method runs on the loop."""

    kind = "loop"

    def __init__(self, node: Any, loop: asyncio.AbstractEventLoop, setter: Any,
                 service_setter: Any, write: int) -> None:
        super().__init__(node, "ROS topic reader failed; reading on")
        self.loop = loop
        self._setter = setter
        self._service_setter = service_setter
        self._write = write
        self._subs: set[ReaderSubscription] = set()
        self._services: set[ReaderService] = set()

    def _add(self, sub: ReaderSubscription) -> None:
        sub.fd = os.eventfd(0, os.EFD_NONBLOCK | os.EFD_CLOEXEC)
        self.loop.add_reader(sub.fd, self._ready, sub)
        with sub.handle:
            rc = self._setter(sub.handle.pointer, self._write, sub.fd)
        self._subs.add(sub)
        if rc != 0:
            self.unsubscribe(sub)
            raise RuntimeError(f"rcl could not wake the bridge for {sub.topic} (rcl error {rc})")

    def _ready(self, sub: ReaderSubscription) -> None:
        try:
            os.eventfd_read(sub.fd)
        except BlockingIOError:
            return
        # Taken: all that is queued, at most a batch. The count the middleware gave is not
        # relied on (rmw implementations count differently); a message that comes after
        # the read writes the eventfd again.
        try:  # the handle is not held: only the loop destroys it, after removing this reader
            batch, took = sub.take(sub.handle, MAX_BATCH)
        except Exception:  # the others are still served
            self.errors.failed(f"taking messages of {sub.topic} failed")
            return
        if took == MAX_BATCH:  # come back for the rest after the others had their turn
            os.eventfd_write(sub.fd, 1)
        if batch:
            sub.deliver(batch, time.time_ns())

    def unsubscribe(self, sub: ReaderSubscription) -> None:
        """Stop the middleware's calls for ``sub`` (they end before this returns), destroy it."""
        if sub in self._subs:
            self._subs.discard(sub)
            self._release(sub.handle, sub.fd, self._setter)

    def serve(self, srv_cls: type[Any], name: str, qos: Any,
              on_request: Callable[[Any, Any], None]) -> ReaderService:
        """Create a service on the node that rclpy's executor does not know of; each request
        wakes the loop, which takes it and calls ``on_request(request, header)``."""
        check_for_type_support(srv_cls)  # type: ignore[no-untyped-call]
        with self.node.handle:
            handle = _rclpy.Service(self.node.handle, srv_cls, name, qos.get_c_qos_profile())
        svc = ReaderService(handle, name, srv_cls.Request, on_request)
        svc.fd = os.eventfd(0, os.EFD_NONBLOCK | os.EFD_CLOEXEC)
        self.loop.add_reader(svc.fd, self._request_ready, svc)
        self._services.add(svc)
        with handle:
            rc = self._service_setter(handle.pointer, self._write, svc.fd)
        if rc != 0:
            self.unserve(svc)
            raise RuntimeError(f"rcl could not wake the bridge for {name} (rcl error {rc})")
        return svc

    def _request_ready(self, svc: ReaderService) -> None:
        try:
            os.eventfd_read(svc.fd)
        except BlockingIOError:
            return
        # Every request queued is taken before any is handed on: handing one on writes to
        # its client's socket, and on loopback the client may run on this CPU at once, so
        # what the loop does after the write (the last, empty take) would wait for it.
        taken = []
        for _ in range(MAX_BATCH):
            try:
                got = svc.handle.service_take_request(svc.request_cls)
            except Exception:
                self.errors.failed(f"taking a request to {svc.name} failed")
                break
            if got is None or got[1] is None:  # nothing left
                break
            taken.append(got)
        else:
            os.eventfd_write(svc.fd, 1)  # come back for the rest after the others had their turn
        for request, header in taken:
            try:
                svc.on_request(request, header)
            except Exception:  # the other requests and services are still served
                self.errors.failed(f"serving a request to {svc.name} failed")

    def unserve(self, svc: ReaderService) -> None:
        """Stop the middleware's calls for ``svc`` (they end before this returns), destroy it."""
        if svc in self._services:
            self._services.discard(svc)
            self._release(svc.handle, svc.fd, self._service_setter)

    def _release(self, handle: Any, fd: int, setter: Any) -> None:
        """Unset the middleware's callback of ``handle`` (no call is running once this
        returns), stop waiting on its eventfd, close it and destroy the handle."""
        with contextlib.suppress(InvalidHandle), handle:
            setter(handle.pointer, None, None)
        with contextlib.suppress(Exception):  # the loop is closing
            self.loop.remove_reader(fd)
        os.close(fd)
        with contextlib.suppress(InvalidHandle):
            handle.destroy_when_not_in_use()

    def stop(self) -> None:
        """Destroy every subscription and service (before the node is destroyed)."""
        for sub in list(self._subs):
            self.unsubscribe(sub)
        for svc in list(self._services):
            self.unserve(svc)


class TopicReader(Reader):
    """A thread that waits on the bridge's topic subscriptions and nothing else.

    ``post(fn, *args)`` runs ``fn(*args)`` on the loop (:meth:`RosNode.post`).
    """

    kind = "thread"

    def __init__(self, context: Any, node: Any, post: Callable[..., None]) -> None:
        super().__init__(node, "ROS topic reader round failed; reading on")
        self.context = context
        self.post = post
        self._subs: tuple[ReaderSubscription, ...] = ()
        self._lock = threading.Lock()
        self._stopping = False
        self._thread: threading.Thread | None = None
        with context.handle:
            self._wake = _rclpy.GuardCondition(context.handle)

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

    def _add(self, sub: ReaderSubscription) -> None:
        with self._lock:
            self._subs = (*self._subs, sub)
        self._wake.trigger_guard_condition()

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
                                        batch, _took = sub.take(sub.handle, MAX_BATCH)
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
