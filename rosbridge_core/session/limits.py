"""Per-connection limits the op groups enforce on their own state (the gate only answers
whether the principal may act on a name at all)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

__all__ = ["over_cap"]


def over_cap(have: Mapping[str, Any], name: str, cap: int, what: str) -> str | None:
    """Why one more ``name`` would pass ``cap`` entries of ``have`` (``None``: it would not,
    or ``name`` is held already, or ``cap`` is 0: no limit)."""
    if cap and name not in have and len(have) >= cap:
        return f"too many {what} on this connection (at most {cap})"
    return None
