"""MockRos: the :class:`~roslibpy_lite.api.Ros` API in memory, for users' unit tests.

No network and no ROS: topics, latched topics and services live in this
object, in the running event loop. Code written against
:class:`~roslibpy_lite.api.Ros` runs unchanged on it::

    from roslibpy_lite.mock import MockRos

    async def test_my_node() -> None:
        ros = MockRos()
        ros.advertise_service("/mult", "mult_msgs/srv/MultFloats",
                              lambda req: {"result": req["x"] * req["y"]})
        await my_node(ros)                       # the code under test
        await ros.drain()                        # let async callbacks finish
        assert ros.published("/cmd") == [{"data": 6.0}]
        ros.inject("/sensor", {"data": 1.5})     # play the robot's side

What it checks, like a real graph would:

- a topic has one type: advertising or subscribing with another type raises
  :class:`~roslibpy_lite.exceptions.UsageError`;
- a published message must fit its type: typed messages are checked against
  their class, dicts against the generated class of the type when there is
  one (:class:`~roslibpy_lite.exceptions.InvalidMessageError` names the field);
- every message travels in its wire form (a JSON round trip), so subscribers
  never share objects with publishers.

Delivery is deterministic: ``publish`` hands the message to every
subscription of the topic before it returns (sync callbacks run at once,
in subscription order); async callbacks run in their subscription's task,
and ``await ros.drain()`` returns once they have taken everything.
Latched topics (``advertise(..., latch=True)``) give late subscribers the
last message. Service calls run the handler directly; a handler that raises
fails the call with :class:`~roslibpy_lite.exceptions.ServiceError`
carrying its text, an unknown service fails the same way, a slow one raises
:class:`~roslibpy_lite.exceptions.RosTimeoutError`.

Connection trouble can be played too: :meth:`MockRos.disconnect` and
:meth:`MockRos.reconnect` move the state like a real drop does (calls in
flight fail with :class:`~roslibpy_lite.exceptions.Disconnected`, publishes
are buffered per publisher, ``offline_buffer`` deep, and delivered on
reconnect).
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Self, overload

from .api import (
    DEFAULT_CALL_TIMEOUT,
    ConnectionState,
    MessageCallback,
    ServiceHandler,
    StateCallback,
)
from .exceptions import (
    ConnectionClosed,
    Disconnected,
    InvalidMessageError,
    RosTimeoutError,
    ServiceError,
    UsageError,
)
from .handles import (
    Publisher,
    ServiceServer,
    StateHub,
    StateWatcher,
    Subscription,
    from_wire,
    lookup_message_class,
    message_type,
    service_type,
    to_wire,
)

if TYPE_CHECKING:
    from types import TracebackType

    from msgs.runtime import Message, Service

    from .api import M

__all__ = ["MockRos"]


@dataclass
class _Topic:
    type_name: str
    latched: Mapping[str, Any] | None = None
    history: list[Mapping[str, Any]] = field(default_factory=list)
    subs: list[Subscription[Any]] = field(default_factory=list)
    publishers: int = 0


def _open_gate(gate: asyncio.Future[None]) -> None:
    if not gate.done():
        gate.set_result(None)


def _wire_copy(wire: Mapping[str, Any], what: str) -> dict[str, Any]:
    try:
        copy: dict[str, Any] = json.loads(json.dumps(wire, allow_nan=False))
    except (TypeError, ValueError) as exc:
        raise InvalidMessageError(f"{what}: not expressible in JSON: {exc}") from None
    return copy


class MockRos:
    """An in-memory :class:`~roslibpy_lite.api.Ros` (see the module docstring).

    Args:
        offline_buffer: messages kept per publisher while :meth:`disconnect`-ed
            (0: publishing then raises Disconnected), as on the real client.
        validate: check dict messages against the generated class of their
            type when there is one (default on).
    """

    def __init__(self, *, offline_buffer: int = 100, validate: bool = True) -> None:
        self.offline_buffer = offline_buffer
        self.validate = validate
        self._hub = StateHub(ConnectionState.CONNECTED)
        self._topics: dict[str, _Topic] = {}
        self._publishers: list[Publisher[Any]] = []
        self._servers: dict[str, ServiceServer] = {}
        self._calls: dict[int, tuple[str, asyncio.Future[None]]] = {}
        self._ids = itertools.count(1)

    def __repr__(self) -> str:
        return f"<MockRos {self._hub.state.value} topics={sorted(self._topics)}>"

    # -- state ---------------------------------------------------------------------------------

    @property
    def state(self) -> ConnectionState:
        """The current (simulated) connection state."""
        return self._hub.state

    @property
    def is_connected(self) -> bool:
        """True while the state is ``CONNECTED``."""
        return self._hub.state is ConnectionState.CONNECTED

    async def wait_connected(self, timeout: float | None = None) -> None:
        """Return once connected (raises RosTimeoutError, or ConnectionClosed once closed)."""
        await self._hub.wait_connected(timeout)

    def on_state_change(self, callback: StateCallback) -> Callable[[], None]:
        """Call ``callback(state)`` on every change; returns a function that removes it."""
        return self._hub.on_change(callback)

    def state_changes(self) -> StateWatcher:
        """An async iterator of the state changes from now on (ends after ``CLOSED``)."""
        return self._hub.watch()

    def disconnect(self) -> None:
        """Play a dropped connection: state ``RECONNECTING``; calls in flight fail."""
        self._check_open()
        self._hub.set(ConnectionState.RECONNECTING)
        calls, self._calls = self._calls, {}
        for service, fut in calls.values():
            if not fut.done():
                fut.set_exception(Disconnected(f"connection dropped while calling {service}"))

    def reconnect(self) -> None:
        """Play a reconnect: state ``CONNECTED``, buffered publishes are delivered."""
        self._check_open()
        self._hub.set(ConnectionState.CONNECTED)
        for pub in list(self._publishers):
            while pub._offline:
                self._deliver(pub.topic, pub._offline.popleft(), record=True, latch=pub.latch)

    def _check_open(self) -> None:
        if self._hub.state is ConnectionState.CLOSED:
            raise ConnectionClosed("the MockRos is closed")

    def _topic(self, topic: str, type_name: str, what: str) -> _Topic:
        entry = self._topics.get(topic)
        if entry is None:
            entry = self._topics[topic] = _Topic(type_name)
        elif entry.type_name != type_name:
            raise UsageError(
                f"{what} {topic}: the topic has type {entry.type_name}, not {type_name}"
            )
        return entry

    # -- test conveniences ---------------------------------------------------------------------

    def published(self, topic: str) -> list[dict[str, Any]]:
        """Every message published on ``topic`` through this mock, oldest first (wire form)."""
        entry = self._topics.get(topic)
        return [dict(m) for m in entry.history] if entry else []

    def inject(
        self,
        topic: str,
        msg: Mapping[str, Any] | Message,
        type: str | type[Message] | None = None,
        *,
        latch: bool = False,
    ) -> None:
        """Deliver ``msg`` to the subscribers of ``topic`` as if the robot published it.

        ``type`` defaults to the topic's known type (or the message's class).
        Not recorded in :meth:`published`. ``latch`` keeps it for late subscribers.
        """
        self._check_open()
        if type is None:
            known = self._topics.get(topic)
            if known is not None:
                type = known.type_name
            elif hasattr(msg, "_type"):
                type = msg._type
            else:
                raise UsageError(f"inject {topic}: the topic has no type yet; pass type=")
        type_name, cls = message_type(type)
        self._topic(topic, type_name, "inject")
        wire = self._check(msg, type_name, cls, f"inject to {topic}")
        self._deliver(topic, wire, record=False, latch=latch)

    def subscribers(self, topic: str) -> int:
        """How many open subscriptions ``topic`` has."""
        entry = self._topics.get(topic)
        return len(entry.subs) if entry else 0

    def served(self) -> list[str]:
        """The names of the services served through this mock."""
        return sorted(self._servers)

    async def drain(self) -> None:
        """Return once every async callback has taken every message delivered so far."""
        while True:
            busy = [s for t in self._topics.values() for s in t.subs
                    if s._async_cbs and (s._queue or not s._idle.is_set())]
            if not busy:
                return
            for sub in busy:
                await sub._drained()

    # -- topics --------------------------------------------------------------------------------

    def _check(
        self, msg: Any, type_name: str, cls: type[Message] | None, what: str
    ) -> dict[str, Any]:
        wire = _wire_copy(to_wire(msg, type_name, cls, what), what)
        if self.validate and cls is None:
            known = lookup_message_class(type_name)
            if known is not None:
                from_wire(wire, known, what)
        return wire

    @overload
    def advertise(
        self, topic: str, type: str, *, latch: bool = False, queue_size: int = 100
    ) -> Publisher[dict[str, Any]]: ...

    @overload
    def advertise(
        self, topic: str, type: type[M], *, latch: bool = False, queue_size: int = 100
    ) -> Publisher[M]: ...

    def advertise(
        self, topic: str, type: str | type[Message], *, latch: bool = False, queue_size: int = 100
    ) -> Publisher[Any]:
        """Announce a publisher (raises UsageError if the topic has another type)."""
        self._check_open()
        type_name, cls = message_type(type)
        entry = self._topic(topic, type_name, "advertise")
        entry.publishers += 1
        pub: Publisher[Any] = Publisher(
            self, topic, type_name, cls, latch=latch, queue_size=queue_size,
            id=f"advertise:{topic}:{next(self._ids)}", offline_buffer=self.offline_buffer,
        )
        self._publishers.append(pub)
        return pub

    def _publish(self, pub: Publisher[Any], wire: Mapping[str, Any]) -> Awaitable[None] | None:
        self._check_open()
        copy = self._check(wire, pub.type_name, None, f"publish to {pub.topic}")
        if self._hub.state is not ConnectionState.CONNECTED:
            if self.offline_buffer == 0:
                raise Disconnected(f"publish to {pub.topic}: the connection is down")
            if len(pub._offline) >= self.offline_buffer:
                pub._offline.popleft()
                pub.dropped += 1
            pub._offline.append(copy)
            return None
        self._deliver(pub.topic, copy, record=True, latch=pub.latch)
        return None

    def _deliver(self, topic: str, wire: Mapping[str, Any], *, record: bool, latch: bool) -> None:
        entry = self._topics[topic]
        if record:
            entry.history.append(wire)
        if latch:
            entry.latched = wire
        for sub in list(entry.subs):
            sub._deliver(wire)

    def _unadvertise(self, pub: Publisher[Any]) -> None:
        if pub in self._publishers:
            self._publishers.remove(pub)
            entry = self._topics.get(pub.topic)
            if entry is not None:
                entry.publishers -= 1

    @overload
    def subscribe(
        self,
        topic: str,
        type: str,
        callback: MessageCallback | None = None,
        *,
        throttle_rate: int = 0,
        queue_length: int = 0,
        compression: str = "none",
        fragment_size: int | None = None,
        buffer_size: int = 100,
    ) -> Subscription[dict[str, Any]]: ...

    @overload
    def subscribe(
        self,
        topic: str,
        type: type[M],
        callback: MessageCallback | None = None,
        *,
        throttle_rate: int = 0,
        queue_length: int = 0,
        compression: str = "none",
        fragment_size: int | None = None,
        buffer_size: int = 100,
    ) -> Subscription[M]: ...

    def subscribe(
        self,
        topic: str,
        type: str | type[Message],
        callback: MessageCallback | None = None,
        *,
        throttle_rate: int = 0,
        queue_length: int = 0,
        compression: str = "none",
        fragment_size: int | None = None,
        buffer_size: int = 100,
    ) -> Subscription[Any]:
        """Subscribe (``throttle_rate``, ``queue_length``, ``fragment_size`` are not simulated)."""
        self._check_open()
        type_name, cls = message_type(type)
        entry = self._topic(topic, type_name, "subscribe")
        sub: Subscription[Any] = Subscription(
            self, topic, type_name, cls, throttle_rate=throttle_rate, queue_length=queue_length,
            compression=compression, fragment_size=fragment_size, buffer_size=buffer_size,
            id=f"subscribe:{topic}:{next(self._ids)}",
        )
        if callback is not None:
            sub.on_message(callback)
        entry.subs.append(sub)
        if entry.latched is not None:
            sub._deliver(entry.latched)
        return sub

    def _unsubscribe(self, sub: Subscription[Any]) -> None:
        entry = self._topics.get(sub.topic)
        if entry is not None and sub in entry.subs:
            entry.subs.remove(sub)

    # -- services ------------------------------------------------------------------------------

    @overload
    async def call_service(
        self,
        service: str,
        type: str,
        args: Mapping[str, Any] | None = None,
        *,
        timeout: float | None = DEFAULT_CALL_TIMEOUT,
    ) -> dict[str, Any]: ...

    @overload
    async def call_service(
        self,
        service: str,
        type: type[Service],
        args: Mapping[str, Any] | Message | None = None,
        *,
        timeout: float | None = DEFAULT_CALL_TIMEOUT,
    ) -> Any: ...

    async def call_service(
        self,
        service: str,
        type: str | type[Service],
        args: Mapping[str, Any] | Message | None = None,
        *,
        timeout: float | None = DEFAULT_CALL_TIMEOUT,
    ) -> Any:
        """Call a service served through this mock (see the module docstring for failures)."""
        self._check_open()
        type_name, srv_cls = service_type(type)
        request_cls = srv_cls.Request if srv_cls else lookup_message_class(f"{type_name}_Request")
        wire = self._check(args if args is not None else {}, f"{type_name}_Request",
                           srv_cls.Request if srv_cls else None, f"call {service}")
        if request_cls is not None and self.validate:
            from_wire(wire, request_cls, f"call {service}")
        if timeout is not None and not timeout > 0:
            raise UsageError(f"call {service}: timeout must be > 0 or None, got {timeout!r}")
        key = next(self._ids)
        task: asyncio.Future[Any] | None = None
        try:
            async with asyncio.timeout(timeout):
                await self._hub.wait_connected()
                server = self._servers.get(service)
                if server is None:
                    raise ServiceError(service, f"service {service} does not exist")
                if server.type_name != type_name:
                    raise ServiceError(
                        service, f"service {service} has type {server.type_name}, not {type_name}"
                    )
                outcome = server.invoke(wire)
                if not isinstance(outcome, tuple):
                    task = asyncio.ensure_future(outcome)
                    gate: asyncio.Future[None] = asyncio.get_running_loop().create_future()
                    self._calls[key] = (service, gate)
                    task.add_done_callback(lambda _: _open_gate(gate))
                    await gate
                    outcome = task.result()
        except TimeoutError:
            raise RosTimeoutError(f"call {service}: no answer within {timeout} s") from None
        finally:
            self._calls.pop(key, None)
            if task is not None and not task.done():
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await task
        ok, values = outcome
        if not ok:
            raise ServiceError(service, str(values))
        response = _wire_copy(
            values if isinstance(values, Mapping) else {}, f"response of {service}"
        )
        response_cls = (
            srv_cls.Response if srv_cls else lookup_message_class(f"{type_name}_Response")
        )
        if response_cls is not None and (self.validate or srv_cls is not None):
            try:
                typed = from_wire(response, response_cls, f"response of {service}")
            except InvalidMessageError as exc:
                raise ServiceError(service, str(exc)) from None
            if srv_cls is not None:
                return typed
        return response

    def advertise_service(
        self, service: str, type: str | type[Service], handler: ServiceHandler
    ) -> ServiceServer:
        """Serve ``service`` with ``handler`` (raises UsageError if it is already served)."""
        self._check_open()
        type_name, srv_cls = service_type(type)
        if service in self._servers:
            raise UsageError(f"advertise_service {service}: already served")
        server = ServiceServer(self, service, type_name, srv_cls, handler,
                               id=f"advertise_service:{service}:{next(self._ids)}")
        self._servers[service] = server
        return server

    def _unadvertise_service(self, server: ServiceServer) -> None:
        if self._servers.get(server.service) is server:
            del self._servers[server.service]

    async def _flush(self) -> None:
        return None

    # -- closing -------------------------------------------------------------------------------

    async def close(self) -> None:
        """Close: state ``CLOSED``; subscriptions end, calls in flight fail (ConnectionClosed)."""
        if self._hub.state is ConnectionState.CLOSED:
            return
        self._hub.set(ConnectionState.CLOSED)
        calls, self._calls = self._calls, {}
        for service, fut in calls.values():
            if not fut.done():
                fut.set_exception(ConnectionClosed(f"MockRos closed while calling {service}"))
        subs = [s for t in self._topics.values() for s in t.subs]
        for sub in subs:
            sub._end()
        for sub in subs:
            consumer = sub._consumer
            if consumer is not None:
                consumer.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await consumer

    async def __aenter__(self) -> Self:
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.close()
