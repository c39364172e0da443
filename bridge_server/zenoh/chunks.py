"""What a key chunk of the relay's wire contract may be: a robot's name and a relay's id
(:func:`check_robot`, :func:`check_relay`: one chunk each), and a goal id's hex
(:data:`HEX`). Below both :mod:`.keys` (the key table) and :mod:`.payloads` (what the keys
carry), which check the names they build or read with these."""

from __future__ import annotations

import re

from rosbridge_core.interfaces import BridgeError

__all__ = ["HEX", "check_relay", "check_robot"]

_CHUNK = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*\Z")
HEX = re.compile(r"(?:[0-9a-f]{2})*\Z")
"""A goal id as the payloads carry it: lower-case hex, two digits a byte."""


def check_robot(robot: str) -> str:
    """``robot`` if it is a usable robot name (one key chunk: letters, digits, ``_ . -``,
    not starting with ``@``); :class:`~rosbridge_core.interfaces.BridgeError` naming it if
    not."""
    if not isinstance(robot, str) or not _CHUNK.match(robot) or len(robot) > 64:
        raise BridgeError(f"invalid robot name {robot!r}: one word of letters, digits, '_', "
                          "'.' and '-' (at most 64 characters), not starting with '.' or '-'")
    return robot


def check_relay(relay: str) -> str:
    """``relay`` if it is a usable relay id (one key chunk, as a robot name)."""
    if not _CHUNK.match(relay):
        raise BridgeError(f"invalid relay id {relay!r}")
    return relay

