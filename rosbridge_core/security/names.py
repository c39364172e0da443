"""ROS 2 name validation, in pure Python (the rules of ``rmw_validate_full_topic_name``).

A full name starts with ``/``, has tokens of ``[A-Za-z0-9_]`` separated by
single slashes, no token starts with a digit, it does not end with ``/`` and
it is at most :data:`MAX_NAME_LENGTH` characters long. Topic, service and
action names follow the same rules. Checking here, before rclpy sees a name,
turns a bad name into one clear ``status`` error instead of an exception
raised deep inside rclpy.
"""

from __future__ import annotations

import re

from rosbridge_core.interfaces import BridgeError

__all__ = ["MAX_NAME_LENGTH", "InvalidNameError", "check_name", ]

MAX_NAME_LENGTH = 247
"""RMW's topic name limit (255) less the DDS prefix ``rt/`` and friends."""

_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
_valid: set[str] = set()


class InvalidNameError(BridgeError, ValueError):
    """A topic, service or action name breaks the ROS 2 naming rules."""


def _problem(name: str) -> str | None:
    if not name.startswith("/"):
        return "it must start with '/'"
    if name == "/":
        return "it names nothing"
    if len(name) > MAX_NAME_LENGTH:
        return f"it is longer than {MAX_NAME_LENGTH} characters"
    if name.endswith("/"):
        return "it must not end with '/'"
    for i, token in enumerate(name[1:].split("/")):
        if token == "":
            return "it has an empty token ('//')"
        if not _TOKEN.match(token):
            if token[0].isdigit():
                return f"token {i + 1} ({token!r}) starts with a digit"
            bad = next(c for c in token if not (c.isascii() and (c.isalnum() or c == "_")))
            return f"character {bad!r} is not allowed (only letters, digits, '_' and '/')"
    return None


def check_name(name: str, what: str = "topic") -> None:
    """Raise :class:`InvalidNameError` if ``name`` is not a valid full ROS 2 name.

    ``what`` ("topic", "service", "action") goes into the message. Valid names
    are remembered, so a name checked once costs a set lookup afterwards.
    """
    if name in _valid:
        return
    problem = _problem(name)
    if problem is not None:
        shown = name if len(name) <= 80 else name[:77] + "..."
        raise InvalidNameError(f"invalid {what} name {shown!r}: {problem}")
    if len(_valid) < 100_000:
        _valid.add(name)

