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

A byte array at the top of the message (an ``Image``'s ``data``) is placed in the text
as its base64 string, and only the fields around it go through the JSON encoder: handed
to the encoder, the 1.2 MB of a camera frame's base64 were scanned again for characters
to escape (base64 has none), which doubled the bridge's time per JSON frame. The base64
itself is :func:`b64_text`'s.
"""

from __future__ import annotations

import binascii
import json
from collections.abc import Callable
from typing import Any

from msgs import cdr
from msgs.runtime import Message, lookup_message

_simd_b64: Callable[[Any], str] | None
try:  # SIMD base64 (the bridge extra installs it): 0.05 ms for a 640x480 rgb8 frame, not 1.2-2.9
    from pybase64 import b64encode_as_string as _simd_b64
except ImportError:  # pragma: no cover - the bridge extra always has it
    _simd_b64 = None

__all__ = ["JsonFromCdr", "b64_text", "encoder_for", "msgs_encoder"]

JsonFromCdr = Callable[[bytes], "str | None"]


def _b64_text_stdlib(data: Any) -> str:
    return binascii.b2a_base64(data, newline=False).decode("ascii")


b64_text: Callable[[Any], str] = _simd_b64 if _simd_b64 is not None else _b64_text_stdlib
"""Standard base64 (with padding, no newline) of a bytes-like object, as ``str``: what
rosbridge puts in JSON for ``uint8``/``char`` arrays. pybase64's SIMD encoder where it is
installed (the bridge extra has it), else the standard library's."""


def _base64(value: Any) -> str:
    if isinstance(value, bytes):
        return b64_text(value)
    raise TypeError(f"{type(value).__name__} is not JSON serializable")


_encode: Callable[[Any], str] = json.JSONEncoder(
    separators=(",", ":"), allow_nan=False, check_circular=False, ensure_ascii=False,
    default=_base64,
).encode


def _is_byte_array(idl: str) -> bool:
    """Whether a field of this IDL type decodes to ``bytes`` (``uint8``/``char`` arrays)."""
    return idl.startswith(("sequence<uint8", "sequence<char", "uint8[", "char["))


def _segments(fields: list[str], byte_fields: set[str]) -> list[tuple[str, ...]]:
    """The fields in order, grouped: a byte array alone, the fields between them together."""
    out: list[tuple[str, ...]] = []
    run: list[str] = []
    for name in fields:
        if name in byte_fields:
            if run:
                out.append(tuple(run))
                run = []
            out.append((name,))
        else:
            run.append(name)
    if run:
        out.append(tuple(run))
    return out


def _same_layout(rclpy_cls: type[Any], msgs_cls: type[Any], depth: int = 0) -> bool:
    """Whether the installed type and msgs' have the same fields, in order, recursively."""
    if depth > 16:
        return False
    theirs = list(rclpy_cls.get_fields_and_field_types().items())
    ours = list(msgs_cls._fields_and_types.items())
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
        msgs_cls = lookup_message(type_name)
    except Exception:
        return None
    if not _same_layout(rclpy_cls, msgs_cls):
        return None
    return msgs_encoder(msgs_cls)


def msgs_encoder(msgs_cls: type[Message]) -> JsonFromCdr:
    """``fn(cdr_bytes) -> JSON text or None`` for a ``msgs`` message class (generated, or
    built from a robot's definitions by :mod:`msgs.dynamic`): what a relay without ROS
    encodes with; ``None`` where the text would differ from rosbridge's (see the module
    docstring)."""
    decode = cdr.decoder_for(msgs_cls)
    encode = _encode
    layout = msgs_cls._fields_and_types
    byte_fields = {name for name, idl in layout.items() if _is_byte_array(idl)}
    if not byte_fields:

        def json_from_cdr(data: bytes) -> str | None:
            try:
                return encode(decode(data))
            except (ValueError, TypeError):  # NaN/Inf (allow_nan=False), undecodable bytes
                return None

        return json_from_cdr

    b64 = b64_text
    # (text before, is a byte array, fields): the byte arrays one by one, the runs of other
    # fields between them together
    plan = [
        (("{" if i == 0 else ",") + (encode(seg[0]) + ':"' if seg[0] in byte_fields else ""),
         seg[0] in byte_fields, seg)
        for i, seg in enumerate(_segments(list(layout), byte_fields))
    ]

    def json_from_cdr_split(data: bytes) -> str | None:
        try:
            values = decode(data)
            parts: list[str] = []
            add = parts.append
            for before, is_bytes, names in plan:
                add(before)
                if is_bytes:
                    add(b64(values[names[0]]))
                    add('"')
                else:  # '{"a":1,"b":2}' without its braces
                    add(encode({name: values[name] for name in names})[1:-1])
            add("}")
            return "".join(parts)  # one copy of the frame's base64, not one per piece
        except (ValueError, TypeError):  # NaN/Inf (allow_nan=False), undecodable bytes
            return None

    return json_from_cdr_split
