"""The Foxglove WebSocket protocol (``foxglove.websocket.v1``) beside rosbridge v2, on one port.

A client that offers the subprotocol in its handshake (Foxglove, Lichtblick, the
``@foxglove/ws-protocol`` client) gets a :class:`FoxgloveSession`; every other client gets
a rosbridge session as before. :mod:`.ops` is the protocol's ops without I/O (parsed, and
the server's frames made), :mod:`.hub` what the Foxglove sessions of a bridge share
(channels, services, watches), :mod:`.session` one client (built of :mod:`.base`,
:mod:`.channels` and :mod:`.parameters`), :mod:`.inbound` the ordered decoding of what a
client publishes. They reach ROS only through the :class:`~rosbridge_core.graph.Graph`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from bridge_server.foxglove.hub import Hub
from bridge_server.foxglove.ops import SUBPROTOCOL
from bridge_server.foxglove.session import FoxgloveSession

__all__ = ["SUBPROTOCOL", "FoxgloveSession", "Hub", "select_subprotocol"]


def select_subprotocol(connection: Any, offered: Sequence[str]) -> Any:
    """websockets' hook: ``foxglove.websocket.v1`` if the client offers it, else none (a
    rosbridge client, which offers nothing or something we do not speak)."""
    return SUBPROTOCOL if SUBPROTOCOL in offered else None
