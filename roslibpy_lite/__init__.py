"""roslibpy_lite: a fast, dependable asyncio client for ROS 2 over rosbridge v2.

Needs only ``websockets``; no ROS installation::

    import roslibpy_lite

    async with roslibpy_lite.connect("ws://robot:9090") as ros:
        pub = await ros.advertise("/chatter", "std_msgs/msg/String")
        await pub.publish({"data": "hello"})

:class:`~roslibpy_lite.mock.MockRos` offers the same API in memory for tests; both are
:class:`~roslibpy_lite.api.Ros` (the front, ``RosBase``) over another transport.
"""

from __future__ import annotations

from ._backoff import Backoff
from .actions import (
    ActionError,
    ActionResult,
    ActionServer,
    GoalContext,
    GoalHandle,
    GoalStatus,
)
from .api import ConnectionState, Ros
from .client import Client, ClientOptions, Connector, connect, run
from .exceptions import (
    ConnectError,
    ConnectionClosed,
    Disconnected,
    DuplicateCallbackWarning,
    Forbidden,
    InvalidMessageError,
    NoMessageYet,
    NotAuthenticated,
    NotConnected,
    PartialMessageWarning,
    RemoteError,
    ReplacedClientWarning,
    ReplacedSubscriptionWarning,
    RosLibError,
    RosLibWarning,
    RosTimeoutError,
    ServiceError,
    StatusError,
    TLSError,
    UsageError,
)
from .handles import Collected, Latest, Publisher, ServiceServer, Subscription
from .messages import RawMessage, define_type
from .mock import MockRos
from .ros import RosBase, RosFront
from .state import StateWatcher

__version__ = "0.1.0"

__all__ = [
    "ActionError",
    "ActionResult",
    "ActionServer",
    "Backoff",
    "Client",
    "ClientOptions",
    "Collected",
    "ConnectError",
    "ConnectionClosed",
    "ConnectionState",
    "Connector",
    "Disconnected",
    "DuplicateCallbackWarning",
    "Forbidden",
    "GoalContext",
    "GoalHandle",
    "GoalStatus",
    "InvalidMessageError",
    "Latest",
    "MockRos",
    "NoMessageYet",
    "NotAuthenticated",
    "NotConnected",
    "PartialMessageWarning",
    "Publisher",
    "RawMessage",
    "RemoteError",
    "ReplacedClientWarning",
    "ReplacedSubscriptionWarning",
    "Ros",
    "RosBase",
    "RosFront",
    "RosLibError",
    "RosLibWarning",
    "RosTimeoutError",
    "ServiceError",
    "ServiceServer",
    "StateWatcher",
    "StatusError",
    "Subscription",
    "TLSError",
    "UsageError",
    "__version__",
    "connect",
    "define_type",
    "run",
]
