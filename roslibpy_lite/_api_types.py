"""The words of the client API that its modules share (re-exported by :mod:`roslibpy_lite.api`).

A leaf: it imports nothing of the client, so :mod:`~roslibpy_lite.api` (the
protocol over the handles) and the modules that make the handles can all use
these without importing each other.
"""

from __future__ import annotations

import enum
from collections.abc import Awaitable, Callable
from typing import TYPE_CHECKING, Any, TypeAlias, TypeVar

if TYPE_CHECKING:
    from msgs.runtime import Message

    from .exceptions import RosLibError

__all__ = [
    "DEFAULT_CALL_TIMEOUT",
    "ConnectionState",
    "ErrorCallback",
    "M",
    "MessageCallback",
    "ServiceHandler",
    "StateCallback",
]

M = TypeVar("M", bound="Message")

DEFAULT_CALL_TIMEOUT = 10.0
"""Seconds a service call waits for its answer unless told otherwise."""


class ConnectionState(enum.Enum):
    """Where a connection is in its life.

    ``CONNECTING`` (first attempt) → ``CONNECTED`` ⇄ ``RECONNECTING`` → ``CLOSED``.
    ``CLOSED`` is final: the client was closed, or the connection dropped and
    reconnecting is off.
    """

    CONNECTING = "connecting"
    CONNECTED = "connected"
    RECONNECTING = "reconnecting"
    CLOSED = "closed"


MessageCallback: TypeAlias = Callable[[Any], "Awaitable[None] | None"]
"""A subscription callback: ``fn(msg)``, sync or ``async``."""

ServiceHandler: TypeAlias = Callable[[Any], Any]
"""A service handler: ``fn(request) -> response``, sync or ``async``.

It receives the request (a dict, or the ``Request`` instance for a typed
service) and returns the response (a dict, a ``Response`` instance, or
``None`` for an empty/default response). If it raises, the caller gets
``result: false`` with the error's text.
"""

StateCallback: TypeAlias = Callable[[ConnectionState], None]
"""Called with each new :class:`ConnectionState`."""

ErrorCallback: TypeAlias = Callable[["RosLibError"], None]
"""An error hook: ``fn(error)`` for a bridge error nobody awaits (see ``on_error``)."""
