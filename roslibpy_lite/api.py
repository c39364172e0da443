"""The API every backend offers: :class:`Ros`, the front itself.

``Ros`` is :class:`~roslibpy_lite.ros.RosBase`, the one declaration of the user API
(its methods, overloads and error rules), which the websocket
:class:`~roslibpy_lite.client.Client` and :class:`~roslibpy_lite.mock.MockRos` both are:
they differ only in their transport. Write robot code against :class:`Ros`; run it on
the client in production and on ``MockRos`` in unit tests. Both return the same
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

from ._api_types import (
    DEFAULT_CALL_TIMEOUT,
    ConnectionState,
    ErrorCallback,
    MessageCallback,
    ServiceHandler,
    StateCallback,
)
from .ros import RosBase as Ros

__all__ = [
    "DEFAULT_CALL_TIMEOUT",
    "ConnectionState",
    "ErrorCallback",
    "MessageCallback",
    "Ros",
    "ServiceHandler",
    "StateCallback",
]
