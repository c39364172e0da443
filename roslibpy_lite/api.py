"""The contract every backend keeps: :class:`Ros`, a ``typing.Protocol``.

Write robot code against :class:`Ros`; run it on the websocket
:class:`~roslibpy_lite.client.Client` in production and on
:class:`~roslibpy_lite.mock.MockRos` in unit tests. Both return the same
handle classes (:class:`~roslibpy_lite.handles.Publisher`,
:class:`~roslibpy_lite.handles.Subscription`,
:class:`~roslibpy_lite.handles.ServiceServer`), and one conformance suite
(``tests/conformance``) runs the same assertions against both.

Message types are given either as a type string (``"std_msgs/msg/String"``
or ``"std_msgs/String"``; messages are then plain dicts in the rosbridge JSON
form) or as a generated class from :mod:`msgs` (``String``; messages are then
instances, validated before they are sent).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, Literal, Protocol, Self, overload, runtime_checkable

from ._api_types import (
    DEFAULT_CALL_TIMEOUT,
    ConnectionState,
    ErrorCallback,
    M,
    MessageCallback,
    ServiceHandler,
    StateCallback,
)

if TYPE_CHECKING:
    from types import TracebackType

    from msgs.runtime import Action, Message, Service

    from . import ops
    from .actions import ActionHandler, ActionServer, FeedbackCallback, GoalHandle
    from .handles import Publisher, ServiceCall, ServiceServer, Subscription
    from .messages import RawMessage
    from .state import StateWatcher

__all__ = [
    "DEFAULT_CALL_TIMEOUT",
    "ConnectionState",
    "ErrorCallback",
    "MessageCallback",
    "Ros",
    "ServiceHandler",
    "StateCallback",
]

@runtime_checkable
class Ros(Protocol):
    """What user code may rely on, whatever the backend."""

    @property
    def state(self) -> ConnectionState:
        """The current connection state."""
        ...

    @property
    def is_connected(self) -> bool:
        """True while the state is ``CONNECTED``."""
        ...

    @property
    def validate(self) -> bool:
        """Whether dict messages are checked against their type's ``msgs`` class."""
        ...

    @validate.setter
    def validate(self, value: bool) -> None: ...

    @property
    def status_errors(self) -> int:
        """``status`` errors from the bridge that named none of our pending requests."""
        ...

    async def wait_connected(self, timeout: float | None = None) -> None:
        """Return once the state is ``CONNECTED``.

        Raises:
            RosTimeoutError: not connected within ``timeout`` seconds.
            ConnectionClosed: the state is (or becomes) ``CLOSED``.
        """
        ...

    def on_state_change(self, callback: StateCallback) -> Callable[[], None]:
        """Call ``callback(state)`` on every change; returns a function that removes it."""
        ...

    def state_changes(self) -> StateWatcher:
        """An async iterator of the state changes from now on (ends after ``CLOSED``)."""
        ...

    def on_status(self, callback: Callable[[ops.Status], None]) -> Callable[[], None]:
        """Call ``callback(status_op)`` for every ``status`` op the bridge sends."""
        ...

    def on_error(self, callback: ErrorCallback) -> Callable[[], None]:
        """Call ``callback(error)`` for each bridge error no caller awaits; returns its remover.

        A refused request that was not awaited, a message the bridge could not
        publish, an error naming no request (each is logged too).
        """
        ...

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
        """Announce a publisher; use as ``await ros.advertise(...)`` or ``async with``."""
        ...

    @overload
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
        raw: Literal[True],
    ) -> Subscription[RawMessage]: ...

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
        raw: Literal[False] = False,
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
        raw: Literal[False] = False,
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
        raw: bool = False,
    ) -> Subscription[Any]:
        """Subscribe; iterate the handle (``async for``) or pass ``callback``."""
        ...

    async def load_types(
        self, *type_names: str, timeout: float | None = DEFAULT_CALL_TIMEOUT
    ) -> list[type[Message] | type[Service] | type[Action]]:
        """Typed classes for the robot's own interfaces (definitions from the bridge)."""
        ...

    @overload
    def call_service(
        self,
        service: str,
        type: str,
        args: Mapping[str, Any] | None = None,
        *,
        timeout: float | None = DEFAULT_CALL_TIMEOUT,
    ) -> ServiceCall[dict[str, Any]]: ...

    @overload
    def call_service(
        self,
        service: str,
        type: type[Service],
        args: Mapping[str, Any] | Message | None = None,
        *,
        timeout: float | None = DEFAULT_CALL_TIMEOUT,
    ) -> ServiceCall[Any]: ...

    def call_service(
        self,
        service: str,
        type: str | type[Service],
        args: Mapping[str, Any] | Message | None = None,
        *,
        timeout: float | None = DEFAULT_CALL_TIMEOUT,
    ) -> ServiceCall[Any]:
        """Call a service; returns the response (dict, or ``Response`` for a typed service)."""
        ...

    def advertise_service(
        self, service: str, type: str | type[Service], handler: ServiceHandler
    ) -> ServiceServer:
        """Serve a service with ``handler``; use as ``await`` or ``async with``."""
        ...

    async def send_goal(
        self,
        action: str,
        type: str | type[Action],
        goal: Mapping[str, Any] | Message | None = None,
        *,
        feedback: bool = True,
        on_feedback: FeedbackCallback | None = None,
        buffer_size: int = 100,
    ) -> GoalHandle:
        """Send a goal to an action server; iterate the handle for feedback, await its result."""
        ...

    def advertise_action(
        self, action: str, type: str | type[Action], handler: ActionHandler
    ) -> ActionServer:
        """Serve an action with ``handler(goal, ctx)``; use as ``await`` or ``async with``."""
        ...

    async def close(self) -> None:
        """Close everything; the state becomes ``CLOSED``."""
        ...

    async def __aenter__(self) -> Self:
        """Use as ``async with``; closes on exit."""
        ...

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        """Close."""
        ...
