"""roslibpy_lite: a fast, dependable asyncio client for ROS 2 over rosbridge v2.

Needs only ``websockets``; no ROS installation::

    import roslibpy_lite

    async with roslibpy_lite.connect("ws://robot:9090") as ros:
        pub = await ros.advertise("/chatter", "std_msgs/msg/String")
        await pub.publish({"data": "hello"})

:class:`~roslibpy_lite.mock.MockRos` offers the same API in memory for tests; both are
:class:`~roslibpy_lite.api.Ros` (the front, ``RosBase``) over another transport.

Importing the package alone loads none of the client: the names below are loaded at their
first use, so the bridge can use the protocol core (:mod:`rosbridge_core.protocol`) without
the client's modules. A test keeps it so (``tests/core/test_protocol_core.py``).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # at run time each name is loaded at its first use (__getattr__ below)
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

from rosbridge_core import __version__ as __version__

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

_CLIENT = ("._backoff", ".actions", ".api", ".client", ".exceptions", ".handles", ".messages",
           ".mock", ".ros", ".state")
"""The modules the names of ``__all__`` come from (those ``TYPE_CHECKING`` imports above).
The first use of any one name loads them all, as ``import roslibpy_lite`` did before."""

if not TYPE_CHECKING:  # type checkers see the imports above, and no catch-all attribute

    def __getattr__(name: str) -> Any:
        """The client's public names, loaded at their first use; a submodule by its name."""
        if name in __all__:
            modules = [importlib.import_module(module, __name__) for module in _CLIENT]
            for export in __all__:
                for module in modules:
                    if export not in globals() and hasattr(module, export):
                        globals()[export] = getattr(module, export)
            return globals()[name]
        if not name.startswith("__"):
            try:
                return importlib.import_module(f".{name}", __name__)
            except ModuleNotFoundError as exc:
                if exc.name != f"{__name__}.{name}":
                    raise
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

    def __dir__() -> list[str]:
        return sorted({*globals(), *__all__})
