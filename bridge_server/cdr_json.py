"""A message's JSON text straight from its CDR bytes, without rclpy deserializing it.

The bridge takes messages serialized. For a JSON subscriber it used to have rclpy
deserialize each into a message object and then encode that. rclpy's deserializer
builds the object through the generated Python classes (``__init__`` and a checked
setter per field), and on a message that arrives alone, with cold caches, that was
the largest share of its time in the bridge: 47 µs for a ``std_msgs/String`` and
156 µs for a ``sensor_msgs/Imu`` at 200 Hz, where the warm figures are 2.4 and 10 µs.

When ``msgs`` generates the same type with the same layout as the one installed
(compared field by field, nested types too: a robot on another ROS release may
differ), :func:`encoder_for` gives a function that decodes the bytes with
``msgs.cdr`` (one compiled decoder per type) and encodes the result with the
standard library's JSON encoder. Its text is the converter's, character for
character (``tests/bridge/test_cdr_json.py`` checks every type ``msgs`` generates):
fields in order, ``uint8``/``char`` arrays as base64, ``byte`` arrays as lists of
ints. Whatever it cannot render the same way it leaves to the converter by
returning ``None``: a NaN or infinity (``null`` there), bytes that do not decode.
"""

from __future__ import annotations

import binascii
import json
from collections.abc import Callable
from typing import Any

from msgs import cdr
from msgs.runtime import lookup_message

__all__ = ["encoder_for"]

JsonFromCdr = Callable[[bytes], "str | None"]


def _base64(value: Any) -> str:
    if isinstance(value, bytes):
        return binascii.b2a_base64(value, newline=False).decode("ascii")
    raise TypeError(f"{type(value).__name__} is not JSON serializable")


_encode: Callable[[Any], str] = json.JSONEncoder(
    separators=(",", ":"), allow_nan=False, check_circular=False, ensure_ascii=False,
    default=_base64,
).encode


def _same_layout(rclpy_cls: type[Any], wire_cls: type[Any], depth: int = 0) -> bool:
    """Whether the installed type and msgs' have the same fields, in order, recursively."""
    if depth > 16:
        return False
    theirs = list(rclpy_cls.get_fields_and_field_types().items())
    ours = list(wire_cls._fields_and_types.items())
    if theirs != ours:
        return False
    for slot in rclpy_cls.SLOT_TYPES:
        nested = getattr(slot, "value_type", slot)  # the item type of an array or sequence
        namespaces = getattr(nested, "namespaces", None)
        if not namespaces:
            continue
        type_name = "/".join((*namespaces, nested.name))
        try:
            module = __import__(".".join(namespaces), fromlist=[nested.name])
            if not _same_layout(getattr(module, nested.name), lookup_message(type_name),
                                depth + 1):
                return False
        except Exception:
            return False
    return True


def encoder_for(rclpy_cls: type[Any], type_name: str) -> JsonFromCdr | None:
    """``fn(cdr_bytes) -> JSON text or None`` for ``rclpy_cls``, or ``None`` if msgs does not
    generate that type with the installed layout (see the module docstring)."""
    try:
        wire_cls = lookup_message(type_name)
    except Exception:
        return None
    if not _same_layout(rclpy_cls, wire_cls):
        return None
    decode = cdr.decoder_for(wire_cls)
    encode = _encode

    def json_from_cdr(data: bytes) -> str | None:
        try:
            return encode(decode(data))
        except (ValueError, TypeError):  # NaN/Inf (allow_nan=False), or undecodable bytes
            return None

    return json_from_cdr
