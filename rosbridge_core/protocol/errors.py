"""The protocol core's errors: the root of every roslibpy_lite error, and the protocol's.

The client's whole tree (:mod:`roslibpy_lite.exceptions`) grows from :class:`RosLibError`;
the bridge raises and answers :class:`ProtocolError` without loading the client.
"""

from __future__ import annotations

__all__ = ["LocalProtocolError", "ProtocolError", "RemoteProtocolError", "RosLibError"]


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
