"""The handshake headers of our extensions to rosbridge v2 (stock servers and clients ignore
them), and :func:`parse_received`, the check of a :data:`RECEIVED_HEADER` value.

Re-exported by :mod:`rosbridge_core.protocol.ops`, where they have always been found.
"""

from __future__ import annotations

from .errors import RemoteProtocolError

__all__ = [
    "ACKS_HEADER",
    "AUTH_HEADER",
    "RECEIVED_HEADER",
    "RELAY_HEADER",
    "SESSION_HEADER",
    "parse_received",
]

ACKS_HEADER = "X-Rosbridge-Acks"
"""Handshake header of our extension: a client that sends it with ``1`` asks the bridge to
confirm each accepted advertise/subscribe/advertise_service/advertise_action with a
``status`` ``info`` naming the request's id (``ok: <op> <name>``); a bridge that will do so
answers the handshake with the same header. Stock servers ignore it, and are then never waited for.
"""

AUTH_HEADER = "X-Rosbridge-Auth"
"""Handshake response header of our bridge: ``required`` when it requires a token and this
connection brought none (it must then send an ``auth`` op first). A client that has no token
to send can fail at once, saying so, instead of failing at its first op."""

RELAY_HEADER = "X-Rosbridge-Relay"
"""Handshake response header of our relay (``roslibpy-lite-relay``): the robot the path
named (empty when it named none). Its refusals say the robot is not connected, or the role may
not reach it, so a client can say "relay" and, for an offline robot, fail at once (or wait for
it when asked) instead of retrying a bare 404."""

SESSION_HEADER = "X-Rosbridge-Session"
"""Handshake header of our extension for sessions that survive a dropped link. A client
sends ``new`` (or the token of the session it had); a bridge that keeps sessions answers
with the token of this connection's session. Stock servers ignore it."""

RECEIVED_HEADER = "X-Rosbridge-Received"
"""Handshake header that goes with a session token, both ways: how many frames the sender
has received in that session. When the bridge answers it, the session was resumed, and each
side sends again what the other has not received."""


def parse_received(value: str | None, limit: int | None) -> int:
    """The frame count of a :data:`RECEIVED_HEADER` value: ASCII decimal digits only, at most
    ``limit`` (what the other side has sent in the session: no one receives more; ``None``:
    the form alone is checked).

    Raises :class:`~roslibpy_lite.exceptions.RemoteProtocolError` with one line naming the
    header and what is wrong with the value (missing, empty, not ASCII digits, too large).
    """
    if value is None:
        raise RemoteProtocolError(f"{RECEIVED_HEADER} is missing: a resumed session needs "
                                  "the count of frames received")
    shown = ascii(value if len(value) <= 24 else value[:24] + "...")
    if not value:
        raise RemoteProtocolError(f"{RECEIVED_HEADER} is empty: expected the count of frames "
                                  "received (ASCII decimal digits)")
    if not (value.isascii() and value.isdigit()):
        raise RemoteProtocolError(f"{RECEIVED_HEADER} {shown} is not a count of frames "
                                  "(ASCII decimal digits only)")
    if limit is None:
        return int(value)
    digits = value.lstrip("0") or "0"  # int() is not asked to read thousands of digits
    count = int(digits) if len(digits) <= len(str(limit)) else limit + 1
    if count > limit:
        raise RemoteProtocolError(f"{RECEIVED_HEADER} {shown} is more than this session has "
                                  f"sent ({limit} frames)")
    return count
