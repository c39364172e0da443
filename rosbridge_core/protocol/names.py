"""ROS names as both ends spell them, normalised in one place.

A client may send ``chatter`` for ``/chatter``: in ROS 2 both name the same topic, so
every table keyed by a name (subscriptions, served services, permissions, rosapi's
answers) keys it by :func:`absolute_name`. A node's full name is its namespace and its
name joined by :func:`node_path`.
"""

from __future__ import annotations

__all__ = ["absolute_name", "node_path"]


def absolute_name(name: str) -> str:
    """``name`` with its leading ``/`` (``chatter`` -> ``/chatter``; ``/chatter`` as it is)."""
    return name if name.startswith("/") else "/" + name


def node_path(namespace: str, name: str) -> str:
    """A node's full name from its namespace and name (``/``, ``talker`` -> ``/talker``;
    ``/robot1/``, ``talker`` -> ``/robot1/talker``)."""
    return namespace.rstrip("/") + "/" + name
