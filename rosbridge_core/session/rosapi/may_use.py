"""``/rosapi/may_*``: what the caller's role may use
(:data:`~rosbridge_core.security.permissions.MAY`; the session's gate keeps the allowed names of
those asked)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from rosbridge_core.security.permissions import MAY
from rosbridge_core.session.rosapi.common import FIELDS, HANDLERS, TYPES, BridgeView, RosapiError

__all__ = ["MAX_ASKED_NAMES"]


MAX_ASKED_NAMES = 10_000
"""The most names one ``/rosapi/may_*`` request may ask about."""


def may_use(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """The names asked (``names``), of which the session's gate keeps the allowed ones."""
    names = args.get("names", [])
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise RosapiError("names: expected a list of names (strings)")
    if len(names) > MAX_ASKED_NAMES:
        raise RosapiError(f"names: {len(names)} names, at most {MAX_ASKED_NAMES} a request")
    return {"names": names}


for _service in MAY:
    HANDLERS[_service] = may_use
    TYPES[_service] = "rosapi_msgs/srv/MayUse"
    FIELDS[_service] = ("names",)
