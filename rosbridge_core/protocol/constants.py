"""The numbers both ends of the protocol agree on, each declared once.

- :data:`DEFAULT_PORT`: where a rosbridge server listens unless told otherwise;
- :data:`POLICY_VIOLATION` and :data:`INTERNAL_ERROR`: the websocket close codes a server
  ends a connection with (RFC 6455, 7.4.1), which a client reads to decide whether to
  reconnect;
- :data:`MAX_MESSAGE_SIZE`: the largest frame a server reads by default;
- :data:`MAX_CLIENT_FRAME`: the largest frame (or reassembled ``fragment`` message) a
  client accepts by default;
- :data:`ADVERTISE_QUEUE_SIZE`: an ``advertise`` op's ``queue_size`` when it names none.
"""

from __future__ import annotations

__all__ = ["ADVERTISE_QUEUE_SIZE", "DEFAULT_PORT", "INTERNAL_ERROR", "MAX_CLIENT_FRAME",
           "MAX_MESSAGE_SIZE", "POLICY_VIOLATION"]

DEFAULT_PORT = 9090
"""rosbridge's port (``ws://robot:9090``)."""

POLICY_VIOLATION = 1008
"""Close code for a failed ``auth`` op, ops before authentication, op floods and revoked
credentials: reconnecting would be refused again."""

INTERNAL_ERROR = 1011
"""Close code for a fault of the server's own while handling the connection."""

MAX_MESSAGE_SIZE = 16 * 1024 * 1024
"""Largest frame a server reads by default (``--max-message-size``), 16 MiB."""

MAX_CLIENT_FRAME = 256 * 1024 * 1024
"""Largest frame, or message reassembled from ``fragment`` ops, a client takes by default
(256 MiB: a point cloud or a 4K image with room to spare)."""

ADVERTISE_QUEUE_SIZE = 100
"""An ``advertise`` op's ``queue_size`` when it names none (rosbridge's default): the
publisher's ROS history depth."""
