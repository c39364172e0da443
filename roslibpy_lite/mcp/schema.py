"""JSON Schema of a ROS message type, from its own definition (msgs' parser).

Each field gets its JSON type, an integer its range (``INTEGER_RANGES``), a ``float32``
its finite range, a bounded string ``maxLength``, an array ``minItems``/``maxItems``
(fixed ``T[n]``, bounded ``T[<=n]``), a default its ``default``; a byte array
(``uint8[]``, ``byte[]``) is base64 text or a list of octets, as rosbridge takes it;
the type's constants are listed under ``x-ros-constants``. Robot-supplied text is cut and
kept as data (:mod:`roslibpy_lite.mcp.listing`).
Nested message types are ``$defs`` entries named by their type (a type met twice is
defined once). No field is required: the bridge fills what a request leaves out.
"""

from __future__ import annotations

from typing import Any

from msgs.parser import (
    FLOAT32_MAX,
    INTEGER_RANGES,
    STRING_TYPES,
    FieldSpec,
    MessageSpec,
    TypeRef,
    parse_message,
)
from msgs.runtime import Message, lookup_message

from .listing import MAX_ROBOT_TEXT, cut_value, quoted

__all__ = ["message_schema", "spec_of"]

_OCTETS = frozenset({"uint8", "byte", "char"})


def spec_of(cls: type[Message]) -> MessageSpec:
    """The parsed definition of a message class (or a service's or action's part)."""
    package, kind, name = cls._type.split("/")
    return parse_message(cls._definition, package, name, kind=kind)  # type: ignore[arg-type]


def _def_name(type_name: str) -> str:
    return type_name.replace("/", ".")


def _scalar(ref: TypeRef, defs: dict[str, Any]) -> dict[str, Any]:
    if ref.package is not None:
        return {"$ref": f"#/$defs/{_def_name(_define(ref.message_type, defs))}"}
    name = ref.name
    if name == "bool":
        return {"type": "boolean"}
    if name in INTEGER_RANGES:
        low, high = INTEGER_RANGES[name]
        return {"type": "integer", "minimum": low, "maximum": high}
    if name == "float32":
        return {"type": "number", "minimum": -FLOAT32_MAX, "maximum": FLOAT32_MAX}
    if name == "float64":
        return {"type": "number"}
    assert name in STRING_TYPES, name
    out: dict[str, Any] = {"type": "string"}
    if ref.string_bound is not None:
        out["maxLength"] = ref.string_bound
    return out


def _field(spec: FieldSpec, defs: dict[str, Any]) -> dict[str, Any]:
    ref = spec.type
    out = _scalar(ref.element, defs)
    if ref.array is not None:
        items = out
        out = {"type": "array", "items": items}
        if ref.array == "fixed":
            out["minItems"] = out["maxItems"] = ref.array_size
        elif ref.array == "bounded":
            out["maxItems"] = ref.array_size
        if ref.name in _OCTETS and ref.package is None:
            out = {"anyOf": [{"type": "string", "contentEncoding": "base64"}, out]}
    out["description"] = str(ref)
    if spec.default is not None:
        out["default"] = cut_value(spec.default)
    return out


def _object(spec: MessageSpec, defs: dict[str, Any]) -> dict[str, Any]:
    """A message type's object schema. The robot's text in it (constants' values, defaults)
    is cut at :data:`~roslibpy_lite.mcp.listing.MAX_ROBOT_TEXT` and kept in data (values,
    ``x-ros-constants``); the description quotes the type's name and counts the constants.
    A field name over that bound leaves the type's fields out (an open object)."""
    text = f"ROS message type {quoted(spec.type_name)}"
    long = sum(len(f.name) > MAX_ROBOT_TEXT for f in spec.fields)
    if long:  # a name is a schema's key, which cannot be cut: no schema of its fields
        return {"type": "object", "description": f"{text}; {long} field names over "
                f"{MAX_ROBOT_TEXT} characters, so its fields are left out here (describe_type "
                "gives its definition)"}
    out: dict[str, Any] = {
        "type": "object",
        "properties": {f.name: _field(f, defs) for f in spec.fields},
        "additionalProperties": False,
    }
    if spec.constants:
        out["x-ros-constants"] = {c.name: cut_value(c.value) for c in spec.constants}
        text += f"; {len(spec.constants)} constants in x-ros-constants (robot data)"
    out["description"] = text
    return out


def _define(type_name: str, defs: dict[str, Any]) -> str:
    key = _def_name(type_name)
    if key not in defs:
        defs[key] = {}  # a placeholder: a recursive type refers to itself
        defs[key] = _object(spec_of(lookup_message(type_name)), defs)
    return type_name


def message_schema(cls: type[Message]) -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of a message of ``cls``, nested types in ``$defs``."""
    defs: dict[str, Any] = {}
    top = _object(spec_of(cls), defs)
    if defs:
        top["$defs"] = defs
    return top
