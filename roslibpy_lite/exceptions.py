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
    └── ConnectionClosed             the connection is gone (the client was closed)
        ├── ConnectError             the connection could not be opened
        │   ├── NotAuthenticated     the bridge refused our token (HTTP 401, or close 1008)
        │   └── TLSError             the TLS handshake failed (a certificate problem)
        └── Disconnected             the connection dropped while this request was in flight,
                                     or a publish found it down and buffering is off

Remote failures (the other side said no) are kept apart from local misuse
(we asked for something invalid), as h11 does. Exceptions from websockets and
the operating system are translated into this tree at the client's edge only.
"""

from __future__ import annotations

__all__ = [
    "ConnectError",
    "ConnectionClosed",
    "Disconnected",
    "Forbidden",
    "InvalidMessageError",
    "LocalProtocolError",
    "NotAuthenticated",
    "ProtocolError",
    "RemoteError",
    "RemoteProtocolError",
    "RosLibError",
    "RosTimeoutError",
    "ServiceError",
    "StatusError",
    "TLSError",
    "UsageError",
]


class RosLibError(Exception):
    """Root of every exception raised by roslibpy_lite."""


class ProtocolError(RosLibError):
    """A frame or op that breaks the rosbridge v2 protocol.

    ``op`` is the op name when it could be read, ``id`` the request id when
    it could be read, so a server can answer the sender with a ``status``
    naming the request.
    """

    def __init__(self, message: str, *, op: str | None = None, id: str | int | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.op = op
        self.id = id


class LocalProtocolError(ProtocolError):
    """We were about to send an op that the protocol does not allow."""


class RemoteProtocolError(ProtocolError):
    """The peer sent a frame or op that the protocol does not allow."""


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


class ConnectionClosed(RosLibError):
    """The connection to the bridge is closed."""


class ConnectError(ConnectionClosed):
    """The connection could not be opened (refused, unreachable, handshake failed)."""


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
