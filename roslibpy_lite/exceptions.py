"""Every error roslibpy_lite raises, under one root.

The tree::

    RosLibError                      root: catch this to catch everything
    ├── ProtocolError                a frame or op that breaks the rosbridge protocol
    │   ├── LocalProtocolError       we were about to send something invalid (our misuse)
    │   └── RemoteProtocolError      the peer sent something invalid
    ├── UsageError                   local misuse of the API (closed handle, bad argument)
    │   └── InvalidMessageError      a message does not fit its type (names the field path)
    ├── RemoteError                  the bridge or ROS reported a failure
    │   ├── ServiceError             a service call answered ``result: false``
    │   ├── ActionError              a goal failed or never ran (in roslibpy_lite.actions)
    │   └── StatusError              the bridge sent a ``status`` error about our request
    │       └── Forbidden            ... because our role may not do that (on that name)
    ├── RosTimeoutError              no answer in time (also a ``TimeoutError``)
    ├── NoMessageYet                 ``sub.latest()`` before any message arrived
    └── ConnectionClosed             the connection is gone (the client was closed)
        ├── ConnectError             the connection could not be opened
        │   ├── NotAuthenticated     the bridge refused our token (HTTP 401, or close 1008)
        │   └── TLSError             the TLS handshake failed (a certificate problem)
        └── Disconnected             the connection dropped while this request was in flight,
            │                        or a publish found it down and buffering is off
            └── NotConnected         the link is down right now (reconnecting): a call, a
                                     read of a fresh value, or an unbuffered publish refused
                                     at once, naming the state

Warnings, under one root too (``warnings.simplefilter("error", RosLibWarning)`` makes
them errors)::

    RosLibWarning                    root (a UserWarning)
    ├── ReplacedClientWarning        sync.connect to a URL this process already had a
    │                                client for: the earlier client was closed
    ├── DuplicateCallbackWarning     a callback subscribed again to a topic: it moved to
    │                                the new subscription instead of running twice
    └── PartialMessageWarning        a dict of a known type misses fields (the bridge
                                     fills in defaults); once per type and field set

The root and the protocol errors are declared in the protocol core
(:mod:`rosbridge_core.protocol.errors`, which the bridge uses without the client) and
belong to this tree as they are.

Remote failures (the other side said no) are kept apart from local misuse
(we asked for something invalid), as h11 does. Exceptions from websockets and
the operating system are translated into this tree at the client's edge only.
"""

from __future__ import annotations

from rosbridge_core.protocol.errors import (
    LocalProtocolError,
    ProtocolError,
    RemoteProtocolError,
    RosLibError,
)

__all__ = [
    "ConnectError",
    "ConnectionClosed",
    "Disconnected",
    "DuplicateCallbackWarning",
    "Forbidden",
    "InvalidMessageError",
    "LocalProtocolError",
    "NoMessageYet",
    "NotAuthenticated",
    "NotConnected",
    "PartialMessageWarning",
    "ProtocolError",
    "RemoteError",
    "RemoteProtocolError",
    "ReplacedClientWarning",
    "RosLibError",
    "RosLibWarning",
    "RosTimeoutError",
    "ServiceError",
    "StatusError",
    "TLSError",
    "UsageError",
]


class UsageError(RosLibError):
    """The API was used in a way it does not allow (a local mistake)."""


class InvalidMessageError(UsageError, ValueError):
    """A message (or service request/response) does not fit its type.

    ``path`` names the field (``pose.position.x``; empty for the message
    itself) when it is known.
    """

    def __init__(self, message: str, *, path: str = "") -> None:
        super().__init__(message)
        self.path = path


class RemoteError(RosLibError):
    """The bridge, or a ROS node behind it, reported a failure."""


class ServiceError(RemoteError):
    """A service call was answered with ``result: false``; the text says why.

    ``reason`` is the answer's text without the ``service <name> failed:``
    prefixes a bridge in between may have added; the message says it once.
    """

    def __init__(self, service: str, reason: str) -> None:
        names = {service, "/" + service.lstrip("/")}
        prefixes = tuple(f"service {name} failed: " for name in names)
        while reason.startswith(prefixes):
            reason = reason.split(": ", 1)[1]
        mentioned = any(f"service {name} " in reason + " " for name in names)
        super().__init__(reason if mentioned else f"service {service} failed: {reason}")
        self.service = service
        self.reason = reason


class StatusError(RemoteError):
    """The bridge answered one of our requests with an error ``status`` op."""

    def __init__(self, message: str, *, level: str = "error", id: str | int | None = None) -> None:
        super().__init__(message)
        self.level = level
        self.id = id


class Forbidden(StatusError):
    """The bridge refused an op because our role may not do it on that name.

    The message names the op, the name and the role (``publish: forbidden:
    role viewer may not publish on /cmd_vel``).
    """


def status_error(message: str, *, level: str = "error", id: str | int | None = None) -> StatusError:
    """The exception for a ``status`` error from the bridge: :class:`Forbidden` when it says so."""
    cls = Forbidden if ": forbidden: " in message else StatusError
    return cls(message, level=level, id=id)


class RosTimeoutError(RosLibError, TimeoutError):
    """No answer arrived within the allowed time."""


class NoMessageYet(RosLibError, LookupError):
    """``sub.latest()`` was asked before the subscription received any message."""


class ConnectionClosed(RosLibError):
    """The connection to the bridge is closed."""


class ConnectError(ConnectionClosed):
    """The connection could not be opened (refused, unreachable, handshake failed).

    ``refused`` is the HTTP status with which a server that did answer said no (401, 403,
    404 or 429: a token, a role, a robot or a path it does not have); ``None`` when no
    server answered as one (nothing listening, a timeout, TLS).
    """

    def __init__(self, *args: object, refused: int | None = None) -> None:
        super().__init__(*args)
        self.refused = refused


class NotAuthenticated(ConnectError):
    """The bridge refused our token: HTTP 401 at the handshake, or a close with code 1008
    (policy violation) because of authentication. Retrying with the same token cannot help,
    so the client does not reconnect."""


class TLSError(ConnectError):
    """The TLS handshake failed: the bridge's certificate could not be verified, or it wants
    a client certificate. The message names the problem in one line."""


class Disconnected(ConnectionClosed):
    """The connection dropped while this request was in flight.

    Also raised by a publish while the connection is down when the client
    was made with ``offline_buffer=0`` (no buffering).
    """


class NotConnected(Disconnected):
    """The link to the bridge is down right now (the client is reconnecting), so the request
    was refused at once rather than left to time out.

    ``state`` is the connection state at the time (``reconnecting``, or ``connecting``).
    Calls that take ``wait_connected=True`` wait for the link instead.
    """

    def __init__(self, message: str, *, state: str) -> None:
        super().__init__(message)
        self.state = state


class RosLibWarning(UserWarning):
    """Root of every warning roslibpy_lite gives."""


class ReplacedClientWarning(RosLibWarning):
    """``sync.connect(url)`` found an open client of this process on the same URL (a
    re-run notebook cell) and closed it, with its thread and subscriptions."""


class DuplicateCallbackWarning(RosLibWarning):
    """A callback was subscribed to a topic it already receives (the same function, or the
    same code from a re-run cell): it moved to the new subscription instead of running twice."""


class ReplacedSubscriptionWarning(RosLibWarning):
    """A notebook cell run again subscribed to a topic it had subscribed to in its earlier
    run: that earlier subscription was closed, so a re-run keeps one."""


class PartialMessageWarning(RosLibWarning):
    """A dict of a type the client knows misses fields; the bridge fills in their defaults.

    Given once per type and set of missing fields; ``strict=True`` refuses such dicts.
    """
