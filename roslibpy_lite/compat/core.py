"""roslibpy's core classes over roslibpy_lite: messages, ``Topic``, ``Service``, ``Param``.

Same names, signatures and behaviour as ``roslibpy.core`` 2.1.0 (see the
package docstring for what differs). Messages are dict-like
(``collections.UserDict``); what goes on the wire is converted to plain dicts.
"""

from __future__ import annotations

import concurrent.futures
import enum
import itertools
import json
import logging
import threading
import time
from collections import UserDict
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, Protocol

from rosbridge_core.protocol.constants import ADVERTISE_QUEUE_SIZE

from ..actions import ActionError
from ..exceptions import RosTimeoutError

if TYPE_CHECKING:
    from ..api import Ros as AioRos
    from ..handles import Publisher, ServiceServer, Subscription
    from ..sync import LoopThread

__all__ = [
    "ActionClient",
    "Feedback",
    "Goal",
    "GoalStatus",
    "Header",
    "Message",
    "Param",
    "Result",
    "RosTimeoutError",
    "Service",
    "ServiceException",
    "ServiceRequest",
    "ServiceResponse",
    "Time",
    "Topic",
]

log = logging.getLogger("roslibpy_lite.compat")

Callback = Callable[..., Any]


class Driver(Protocol):
    """What :class:`Topic`, :class:`Service`, :class:`Param` and :class:`ActionClient` use of
    the :class:`~roslibpy_lite.compat.Ros` they are given (it is one)."""

    @property
    def is_connected(self) -> bool:
        """True while the connection is open."""
        ...

    @property
    def loop_thread(self) -> LoopThread:
        """The thread whose asyncio loop runs the connection."""
        ...

    def run_blocking(self, what: str, fn: Callable[[AioRos], Any]) -> Any:
        """Run ``fn(client)`` on the loop once connected; block for its result."""
        ...

    def run_when_connected(
        self,
        fn: Callable[[AioRos], Any],
        done: Callable[[concurrent.futures.Future[Any]], None] | None = None,
    ) -> None:
        """Run ``fn(client)`` on the loop once connected, without waiting (in call order)."""
        ...

    def run_on_callback_thread(
        self, callback: Callback, *args: Any
    ) -> concurrent.futures.Future[Any] | None:
        """Run ``callback(*args)`` on the callback thread."""
        ...

    async def run_on_callback_thread_and_wait(self, callback: Callback, *args: Any) -> None:
        """Run ``callback(*args)`` on the callback thread; return once it ran."""
        ...

    def request_service(
        self,
        service: str,
        type_name: str,
        args: dict[str, Any],
        callback: Callback | None,
        errback: Callback | None,
        timeout: float | None,
    ) -> ServiceResponse | None:
        """Call a service blocking (returns the response) or with callback/errback."""
        ...


class _Values(UserDict[str, Any]):
    def __init__(self, values: Mapping[str, Any] | None = None) -> None:
        super().__init__()
        if values is not None:
            self.update(values)


class Message(_Values):
    """A message: a dict."""


class ServiceRequest(_Values):
    """The request of a service call: a dict."""


class ServiceResponse(_Values):
    """The response of a service call: a dict."""


class Goal(_Values):
    """An action goal: a dict."""


class Feedback(_Values):
    """Action feedback: a dict."""


class Result(_Values):
    """An action result: a dict."""


class GoalStatus(enum.Enum):
    """ROS 2 goal states (action_msgs/msg/GoalStatus)."""

    UNKNOWN = 0
    ACCEPTED = 1
    EXECUTING = 2
    CANCELING = 3
    SUCCEEDED = 4
    CANCELED = 5
    ABORTED = 6


class Time(UserDict[str, int]):
    """ROS time as two integers: seconds since the epoch and nanoseconds since that second."""

    def __init__(self, secs: float, nsecs: float) -> None:
        super().__init__()
        self.data["secs"] = _int(secs)
        self.data["nsecs"] = _int(nsecs)

    @property
    def secs(self) -> int:
        """Seconds since the epoch."""
        return self.data["secs"]

    @property
    def nsecs(self) -> int:
        """Nanoseconds since :attr:`secs`."""
        return self.data["nsecs"]

    def is_zero(self) -> bool:
        """True when both parts are 0."""
        return self.secs == 0 and self.nsecs == 0

    def to_nsec(self) -> int:
        """Nanoseconds since the epoch."""
        return self.secs * 1_000_000_000 + self.nsecs

    def to_sec(self) -> float:
        """Seconds since the epoch, as a float (like ``time.time()``)."""
        return self.secs + self.nsecs / 1e9

    @staticmethod
    def from_sec(float_secs: float) -> Time:
        """The Time of a float number of seconds."""
        secs = int(float_secs)
        return Time(secs, int((float_secs - secs) * 1_000_000_000))

    @staticmethod
    def now() -> Time:
        """The system clock's time now (not ROS time)."""
        return Time.from_sec(time.time())


def _int(n: float) -> int:
    if isinstance(n, int):
        return n
    if isinstance(n, float) and n.is_integer():
        return int(n)
    raise ValueError("argument must be an integer")


class Header(UserDict[str, Any]):
    """A ROS 1 ``std_msgs/Header`` (seq, stamp, frame_id); ROS 2's is ``compat.ros2.Header``."""

    def __init__(
        self, seq: int | None = None, stamp: Mapping[str, int] | None = None,
        frame_id: str | None = None,
    ) -> None:
        super().__init__()
        self.data["seq"] = seq
        self.data["stamp"] = Time(stamp["secs"], stamp["nsecs"]) if stamp else None
        self.data["frame_id"] = frame_id


class ServiceException(Exception):
    """A service call failed (the service answered ``result: false``)."""


def plain(value: Any) -> Any:
    """``value`` with every dict-like (Message, Time, Header ...) turned into a plain dict."""
    if isinstance(value, UserDict | Mapping):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    return value


class Topic:
    """Publish and/or subscribe to a topic, as ``roslibpy.Topic``.

    Args:
        ros: the :class:`~roslibpy_lite.compat.Ros` connection.
        name: the topic name, e.g. ``/cmd_vel``.
        message_type: e.g. ``std_msgs/String``.
        compression: ``"none"``; ``"png"`` is accepted and sent as plain JSON.
        latch: latch published messages (late subscribers get the last one).
        throttle_rate: milliseconds between messages, at the bridge.
        queue_size: the bridge's publisher queue.
        queue_length: the bridge's queue for this subscription.
        reconnect_on_close: accepted; roslibpy_lite always restores after a reconnect.
    """

    SUPPORTED_COMPRESSION_TYPES = ("png", "none")

    def __init__(
        self,
        ros: Driver,
        name: str,
        message_type: str,
        compression: str | None = None,
        latch: bool = False,
        throttle_rate: int = 0,
        queue_size: int = ADVERTISE_QUEUE_SIZE,
        queue_length: int = 0,
        reconnect_on_close: bool = True,
    ) -> None:
        self.ros = ros
        self.name = name
        self.message_type = message_type
        self.compression = compression or "none"
        if self.compression not in self.SUPPORTED_COMPRESSION_TYPES:
            raise ValueError("Unsupported compression type. Must be one of: "
                             + str(self.SUPPORTED_COMPRESSION_TYPES))
        self.latch = latch
        self.throttle_rate = throttle_rate
        self.queue_size = queue_size
        self.queue_length = queue_length
        self.reconnect_on_close = reconnect_on_close
        self._advertised = False
        self._subscribed = False
        self._pub: Publisher[Any] | None = None
        self._sub: Subscription[Any] | None = None

    @property
    def is_advertised(self) -> bool:
        """True while advertised as a publisher of this topic."""
        return self._advertised

    @property
    def is_subscribed(self) -> bool:
        """True while subscribed."""
        return self._subscribed

    def subscribe(self, callback: Callable[[dict[str, Any]], Any]) -> None:
        """Call ``callback(message)`` (on the callback thread) for every message on the topic."""
        if self._subscribed:
            return
        self._subscribed = True
        ros = self.ros

        async def deliver(msg: dict[str, Any]) -> None:
            # One message at a time; the bridge's queue and our buffer bound the backlog.
            await ros.run_on_callback_thread_and_wait(callback, msg)

        def open_(client: AioRos) -> Subscription[Any]:
            self._sub = client.subscribe(self.name, self.message_type, deliver,
                                         throttle_rate=self.throttle_rate,
                                         queue_length=self.queue_length)
            self._sub.uint8_as_sent = True  # base64 text under JSON, as roslibpy gives
            return self._sub

        ros.run_when_connected(open_)

    def unsubscribe(self) -> None:
        """Stop the subscription."""
        if not self._subscribed:
            return
        self._subscribed = False
        if self.ros.loop_thread.closing:  # terminated: closed with the connection
            return
        self.ros.run_when_connected(lambda client: self._sub.unsubscribe() if self._sub else None)

    def advertise(self) -> None:
        """Announce this client as a publisher of the topic."""
        if self._advertised:
            return
        self._advertised = True

        def open_(client: AioRos) -> Publisher[Any]:
            self._pub = client.advertise(self.name, self.message_type, latch=self.latch,
                                         queue_size=self.queue_size)
            return self._pub

        self.ros.run_when_connected(open_)

    def publish(self, message: Mapping[str, Any]) -> None:
        """Publish ``message`` (advertising first if needed).

        While connected it returns once the message is handed to the
        connection and raises what went wrong; before the first connection
        it is queued, as roslibpy does.
        """
        if not self._advertised:
            self.advertise()
        msg = plain(message)

        def send(client: AioRos) -> Any:
            assert self._pub is not None
            return self._pub.publish(msg)

        if self.ros.is_connected:
            self.ros.run_blocking(f"publish {self.name}", send)
        else:
            self.ros.run_when_connected(send)

    def unadvertise(self) -> None:
        """Stop publishing."""
        if not self._advertised:
            return
        self._advertised = False
        if self.ros.loop_thread.closing:  # terminated: closed with the connection
            return
        self.ros.run_when_connected(lambda client: self._pub.unadvertise() if self._pub else None)


class Service:
    """Call a service or serve one, as ``roslibpy.Service``.

    Args:
        ros: the :class:`~roslibpy_lite.compat.Ros` connection.
        name: the service name, e.g. ``/add_two_ints``.
        service_type: e.g. ``std_srvs/SetBool``.
        reconnect_on_close: accepted; roslibpy_lite always restores after a reconnect.
    """

    def __init__(
        self, ros: Driver, name: str, service_type: str, reconnect_on_close: bool = True
    ) -> None:
        self.ros = ros
        self.name = name
        self.service_type = service_type
        self.reconnect_on_close = reconnect_on_close
        self._is_advertised = False
        self._server: ServiceServer | None = None

    @property
    def is_advertised(self) -> bool:
        """True while this instance serves the service."""
        return self._is_advertised

    def call(
        self,
        request: Mapping[str, Any],
        callback: Callback | None = None,
        errback: Callback | None = None,
        timeout: float | None = None,
    ) -> ServiceResponse | None:
        """Call the service.

        Without ``callback`` it blocks and returns the :class:`ServiceResponse`
        (raises :class:`ServiceException` when the call fails, RosTimeoutError
        after ``timeout`` seconds). With ``callback`` it returns at once;
        ``callback(response)`` or ``errback(reason)`` runs on the callback thread.
        """
        if self._is_advertised:
            return None
        return self.ros.request_service(self.name, self.service_type, plain(request), callback,
                                        errback, timeout)

    def advertise(self, callback: Callable[[Any, ServiceResponse], bool]) -> None:
        """Serve the service with ``callback(request, response) -> bool``.

        The handler fills ``response`` and returns True; returning False (or
        raising) fails the caller's call. Handlers run on a worker thread.
        """
        if self._is_advertised:
            return
        if not callable(callback):
            raise ValueError("Callback is not a valid callable")
        name = self.name

        def handler(request: Any) -> dict[str, Any]:
            response = ServiceResponse()
            if not callback(request, response):
                raise ServiceException(f"the handler of {name} did not succeed")
            result: dict[str, Any] = plain(response)
            return result

        serve = self.ros.loop_thread.off_loop(handler)
        self._is_advertised = True

        def open_(client: AioRos) -> ServiceServer:
            self._server = client.advertise_service(self.name, self.service_type, serve)
            return self._server

        self.ros.run_when_connected(open_)

    def unadvertise(self) -> None:
        """Stop serving."""
        if not self._is_advertised:
            return
        self._is_advertised = False
        if self.ros.loop_thread.closing:  # terminated: closed with the connection
            return
        self.ros.run_when_connected(
            lambda client: self._server.unadvertise() if self._server else None)


class Param:
    """A ROS parameter (``/node:name`` in ROS 2), as ``roslibpy.Param``."""

    def __init__(self, ros: Driver, name: str) -> None:
        self.ros = ros
        self.name = name

    def get(
        self, callback: Callback | None = None, errback: Callback | None = None,
        timeout: float | None = None,
    ) -> Any:
        """The value (blocking unless ``callback`` is given, which then gets the value)."""
        on_result = None if callback is None else (
            lambda result: callback(json.loads(result["value"])))
        result = self.ros.request_service("/rosapi/get_param", "rosapi_msgs/srv/GetParam",
                                          {"name": self.name}, on_result, errback, timeout)
        return None if result is None else json.loads(result["value"])

    def set(
        self, value: Any, callback: Callback | None = None, errback: Callback | None = None,
        timeout: float | None = None,
    ) -> None:
        """Set the value."""
        self.ros.request_service("/rosapi/set_param", "rosapi_msgs/srv/SetParam",
                                 {"name": self.name, "value": json.dumps(value)}, callback, errback,
                                 timeout)

    def delete(
        self, callback: Callback | None = None, errback: Callback | None = None,
        timeout: float | None = None,
    ) -> None:
        """Delete the parameter."""
        self.ros.request_service("/rosapi/delete_param", "rosapi_msgs/srv/DeleteParam",
                                 {"name": self.name}, callback, errback, timeout)


class ActionClient:
    """Send goals to a ROS 2 action server, as ``roslibpy.ActionClient``.

    Args:
        ros: the :class:`~roslibpy_lite.compat.Ros` connection.
        name: the action name, e.g. ``/fibonacci``.
        action_type: e.g. ``example_interfaces/action/Fibonacci``.
        reconnect_on_close: accepted (roslibpy ignores it too).

    Callbacks run on the callback thread, feedback before the result. As in
    roslibpy, a goal that does not succeed (canceled, aborted, rejected, no
    such action server) goes to ``errback`` with ``{"status": GoalStatus,
    "values": ...}``; a succeeded one to ``resultback`` with a :class:`Result`
    ``{"status": GoalStatus.SUCCEEDED, "values": {...}}``.
    """

    def __init__(self, ros: Driver, name: str, action_type: str,
                 reconnect_on_close: bool = True) -> None:
        self.ros = ros
        self.name = name
        self.action_type = action_type
        self.reconnect_on_close = reconnect_on_close
        self._is_advertised = False
        self.wait_results: dict[str, threading.Event] = {}
        self._goals: dict[str, Any] = {}  # goal id -> asyncio GoalHandle (on the loop)
        self._cancel_wanted: set[str] = set()
        self._ids = itertools.count(1)

    def send_goal(self, goal: Mapping[str, Any], resultback: Callback | None,
                  feedback: Callback | None, errback: Callback | None) -> str | None:
        """Send ``goal``; returns its id at once (callbacks report the rest)."""
        if self._is_advertised:
            return None
        goal_id = f"send_action_goal:{self.name}:{next(self._ids)}"
        finished = self.wait_results[goal_id] = threading.Event()
        ros, args = self.ros, plain(goal)

        def on_feedback(values: Any) -> None:
            if feedback is not None:
                ros.run_on_callback_thread(feedback, Feedback(values))

        def report(callback: Callback | None, value: Any) -> None:
            try:
                if callback is not None:
                    callback(value)
            finally:
                finished.set()

        async def run(client: AioRos) -> None:
            try:
                handle = await client.send_goal(self.name, self.action_type, args,
                                                on_feedback=on_feedback)
                self._goals[goal_id] = handle
                if goal_id in self._cancel_wanted:
                    await handle.cancel()
                outcome = await handle.result()
            except ActionError as exc:
                ros.run_on_callback_thread(report, errback, {"status": GoalStatus(int(exc.status)),
                                                "values": exc.reason})
            except Exception as exc:
                ros.run_on_callback_thread(report, errback, {"status": GoalStatus.UNKNOWN,
                                                "values": str(exc)})
            else:
                status = GoalStatus(int(outcome.status))
                values = outcome.values if outcome.values is not None else outcome.text
                if outcome.values is not None:  # it ran to a final status, canceled too:
                    # as stock roslibpy
                    ros.run_on_callback_thread(
                        report, resultback, Result({"status": status, "values": values}))
                else:
                    ros.run_on_callback_thread(
                        report, errback, {"status": status, "values": values})
            finally:
                self._goals.pop(goal_id, None)
                self._cancel_wanted.discard(goal_id)

        self.ros.run_when_connected(run)
        return goal_id

    def cancel_goal(self, goal_id: str) -> None:
        """Ask the action server to cancel the goal ``goal_id`` (its errback follows)."""

        async def cancel(client: AioRos) -> None:
            handle = self._goals.get(goal_id)
            if handle is None:
                self._cancel_wanted.add(goal_id)  # not sent yet: cancelled once it is
            else:
                await handle.cancel()

        self.ros.run_when_connected(cancel)

    def wait_goal(self, goal_id: str, timeout: float | None = None) -> None:
        """Block until the goal's callback has run (raises RosTimeoutError after ``timeout``)."""
        event = self.wait_results.get(goal_id)
        if event is None:
            raise ValueError("Unknown goal ID")
        if not event.wait(timeout):
            raise RosTimeoutError("Goal failed to receive result")
        self.wait_results.pop(goal_id, None)
