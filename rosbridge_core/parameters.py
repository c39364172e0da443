"""A node's parameter values as the Graph's parameter methods give and take them: plain
Python values, and ``rcl_interfaces/msg/ParameterValue`` (one field per type) both ways.
Declared once for every Graph (rclpy, in memory, the relay)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["PARAMETER_EVENTS", "PARAMETER_KINDS", "PARAMETER_TYPE_NAMES", "parameter_obj",
           "parameter_value"]

PARAMETER_EVENTS = "/parameter_events"
"""The topic on which every node reports changes to its parameters."""

def _all(kind: type | tuple[type, ...]) -> Callable[[Any], bool]:
    return lambda v: isinstance(v, list) and all(isinstance(x, kind) for x in v)


PARAMETER_KINDS: tuple[tuple[int, str, Callable[[Any], bool]], ...] = (
    (1, "bool_value", lambda v: isinstance(v, bool)),
    (2, "integer_value", lambda v: isinstance(v, int)),
    (3, "double_value", lambda v: isinstance(v, float)),
    (4, "string_value", lambda v: isinstance(v, str)),
    (5, "byte_array_value", lambda v: isinstance(v, bytes | bytearray)),
    (6, "bool_array_value", _all(bool)),
    (7, "integer_array_value", _all(int)),
    (8, "double_array_value", _all((int, float))),
    (9, "string_array_value", _all(str)),
)
"""``rcl_interfaces/msg/ParameterType`` numbers, each with the ``ParameterValue`` field that
holds it and what plain value it takes (in the order a value is tried: a ``bool`` is no
integer here, a list of ints an integer array)."""

PARAMETER_TYPE_NAMES = ("NOT_SET", "BOOL", "INTEGER", "DOUBLE", "STRING", "BYTE_ARRAY",
                        "BOOL_ARRAY", "INTEGER_ARRAY", "DOUBLE_ARRAY", "STRING_ARRAY")
"""rclpy's ``Parameter.Type`` names, by number."""

_PARAMETER_FIELDS = {kind: field for kind, field, _ in PARAMETER_KINDS}


def parameter_obj(value: Any) -> dict[str, Any]:
    """A plain value (as :func:`parameter_value` gives it) as a
    ``rcl_interfaces/msg/ParameterValue`` object: its ``type`` and the one field that holds
    it (``None``: not set; ``bytes``: a byte array, as a list of ints; a double array's ints
    as floats). ``ValueError`` for what a parameter cannot hold."""
    if value is None:
        return {"type": 0}
    for kind, field, test in PARAMETER_KINDS:
        if test(value):
            if kind == 5:
                return {"type": 5, field: list(value)}
            return {"type": kind, field: [float(v) for v in value] if kind == 8 else value}
    raise ValueError("args.value: a ROS 2 parameter is a bool, int, float, string or a list "
                     f"of one of those, got {type(value).__name__}")


def parameter_value(value: Any) -> Any:
    """A ``rcl_interfaces/msg/ParameterValue`` as the plain value the Graph's parameter
    methods give and take: ``bool``, ``int``, ``float``, ``str``, ``bytes`` for a byte
    array (its type is kept: a list of ints would read as an integer array), a ``list``
    for the other arrays, ``None`` when not set. ``value`` is an rclpy message or a
    mapping (as decoded from CDR); a byte array's items are ints or 1-byte ``bytes``
    (rclpy's)."""
    def field(name: str) -> Any:
        return value[name] if isinstance(value, Mapping) else getattr(value, name)

    name = _PARAMETER_FIELDS.get(int(field("type")))
    if name is None:
        return None
    found = field(name)
    if name == "byte_array_value":
        return b"".join(b if isinstance(b, bytes) else bytes((b,)) for b in found)
    return [*found] if name.endswith("_array_value") else found
