"""ROS 2 parameter values as ``ros2 param`` shows and reads them.

A node's parameter services (``/node/get_parameters``, ``/node/set_parameters``, ...) carry
``rcl_interfaces/msg/ParameterValue``: a ``type`` (1 bool ... 9 string array) and one field
holding the value. This module turns those into Python values and back, with ``ros2
param``'s rules: ``param set`` guesses the type from YAML text as rclpy's
``get_parameter_value`` does; ``param dump`` writes ``/node: {ros__parameters: {...}}`` with
nested names (``a.b``) as nested mappings; ``param load`` reads that file back. Pure
functions, no I/O: tests hold the formats without a robot.
"""

from __future__ import annotations

import base64
from collections.abc import Iterable, Mapping
from typing import Any

from .format import ArgumentError

__all__ = [
    "NOT_SET",
    "ParameterFileError",
    "dump_yaml",
    "get_line",
    "guess_value",
    "parameters_from_yaml",
    "to_python",
    "type_name",
    "typed_value",
]

NOT_SET, BOOL, INTEGER, DOUBLE, STRING = 0, 1, 2, 3, 4
BYTE_ARRAY, BOOL_ARRAY, INTEGER_ARRAY, DOUBLE_ARRAY, STRING_ARRAY = 5, 6, 7, 8, 9

_FIELDS = {
    BOOL: "bool_value", INTEGER: "integer_value", DOUBLE: "double_value",
    STRING: "string_value", BYTE_ARRAY: "byte_array_value", BOOL_ARRAY: "bool_array_value",
    INTEGER_ARRAY: "integer_array_value", DOUBLE_ARRAY: "double_array_value",
    STRING_ARRAY: "string_array_value",
}
"""ParameterType -> the ParameterValue field holding the value."""

_TYPE_NAMES = {
    BOOL: "boolean", INTEGER: "integer", DOUBLE: "double", STRING: "string",
    BYTE_ARRAY: "byte array", BOOL_ARRAY: "boolean array", INTEGER_ARRAY: "integer array",
    DOUBLE_ARRAY: "double array", STRING_ARRAY: "string array", NOT_SET: "not set",
}
"""ParameterType -> the name ``ros2 param describe`` and ``list --param-type`` print."""

_GET_LABELS = {
    BOOL: "Boolean value is:", INTEGER: "Integer value is:", DOUBLE: "Double value is:",
    STRING: "String value is:", BYTE_ARRAY: "Byte values are:",
    BOOL_ARRAY: "Boolean values are:", INTEGER_ARRAY: "Integer values are:",
    DOUBLE_ARRAY: "Double values are:", STRING_ARRAY: "String values are:",
}
"""ParameterType -> the label ``ros2 param get`` prints before the value."""

WILDCARD = "/**"
"""The key of a parameter file's entry that applies to every node."""

SEPARATOR = "."
"""What joins the parts of a nested parameter name (``a.b``)."""


class ParameterFileError(ArgumentError):
    """A parameter file is not in ``ros2 param dump``'s format (the text says where)."""


def type_name(type_: int) -> str:
    """The name ``ros2 param`` gives a ParameterType (``double array``)."""
    return _TYPE_NAMES.get(type_, f"unknown type {type_}")


def _bytes(value: Any) -> list[int]:
    """A ``byte[]`` field as a list of ints, whichever form the wire gave it in."""
    if isinstance(value, str):
        return list(base64.b64decode(value))
    if isinstance(value, bytes | bytearray):
        return list(value)
    return [int(v) for v in value]


def to_python(value: Mapping[str, Any]) -> Any:
    """The Python value of a ParameterValue's wire form (None when not set).

    Raises:
        ValueError: the type is none ParameterType defines.
    """
    type_ = int(value.get("type", NOT_SET))
    if type_ == NOT_SET:
        return None
    field = _FIELDS.get(type_)
    if field is None:
        raise ValueError(f"unknown parameter type {type_}")
    raw = value.get(field)
    if type_ == BYTE_ARRAY:
        return _bytes(raw or [])
    if type_ in (BOOL_ARRAY, INTEGER_ARRAY, DOUBLE_ARRAY, STRING_ARRAY):
        return list(raw or [])
    return raw


def get_line(value: Mapping[str, Any], hide_type: bool = False) -> str:
    """What ``ros2 param get`` prints for a ParameterValue (``Integer value is: 5``)."""
    type_ = int(value.get("type", NOT_SET))
    if type_ == NOT_SET:
        return "None" if hide_type else "Parameter not set."
    shown = to_python(value)
    if type_ == BYTE_ARRAY:  # rclpy holds a byte array as one-byte bytes objects
        shown = [bytes([b]) for b in shown]
    text = str(shown)
    return text if hide_type else f"{_GET_LABELS[type_]} {text}"


def _wire(type_: int, value: Any) -> dict[str, Any]:
    return {"type": type_, _FIELDS[type_]: value}


def typed_value(value: Any, where: str) -> dict[str, Any]:
    """The ParameterValue wire form of a YAML value (bool, int, float, str, or a list of one
    of them), as rclpy types them; an empty list is a boolean array, as in rclpy.

    Raises:
        ArgumentError: the value is none of those (``where`` names it in the text).
    """
    if isinstance(value, bool):
        return _wire(BOOL, value)
    if isinstance(value, int):
        return _wire(INTEGER, value)
    if isinstance(value, float):
        return _wire(DOUBLE, value)
    if isinstance(value, str):
        return _wire(STRING, value)
    if isinstance(value, list):
        for type_, kind in ((BOOL_ARRAY, bool), (INTEGER_ARRAY, int), (DOUBLE_ARRAY, float),
                            (STRING_ARRAY, str)):
            if all(isinstance(v, kind) and (kind is bool or not isinstance(v, bool))
                   for v in value):
                return _wire(type_, list(value))
        raise ArgumentError(f"{where}: a list parameter holds one type (bools, integers, "
                            f"doubles or strings), got {value!r}")
    raise ArgumentError(f"{where}: a parameter is a bool, integer, double, string or a list "
                        f"of one of them, got {type(value).__name__} {value!r}")


def guess_value(text: str) -> dict[str, Any]:
    """The ParameterValue ``ros2 param set`` makes of ``text``: read as YAML (``5`` is an
    integer, ``[1.0, 2.5]`` a double array, ``true`` a boolean), else the text as a string;
    a list of mixed types is the text as a string, as rclpy does."""
    import yaml

    try:
        value = yaml.safe_load(text)
    except yaml.YAMLError:
        value = text
    if value is None:
        return _wire(STRING, text)
    try:
        return typed_value(value, "VALUE")
    except ArgumentError:
        return _wire(STRING, text)


def _nest(flat: Mapping[str, Any]) -> dict[str, Any]:
    """``{"a.b": 1, "c": 2}`` -> ``{"a": {"b": 1}, "c": 2}``, as ``ros2 param dump`` nests."""
    nested: dict[str, Any] = {}
    for name, value in flat.items():
        *parents, leaf = name.split(SEPARATOR)
        level = nested
        for part in parents:
            level = level.setdefault(part, {})
        level[leaf] = value
    return nested


def dump_yaml(node: str, values: Mapping[str, Any]) -> str:
    """``ros2 param dump``'s text for ``node`` (its full name) and its parameters' values
    (by name): ``/node:\\n  ros__parameters:\\n    name: value\\n``, keys sorted, block style."""
    import yaml

    document = {node: {"ros__parameters": _nest(values)}}
    return str(yaml.safe_dump(document, default_flow_style=False))


def _flatten(prefix: str, table: Mapping[str, Any]) -> Iterable[tuple[str, Any]]:
    for key, value in table.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            yield from _flatten(name + SEPARATOR, value)
        else:
            yield name, value


def parameters_from_yaml(text: str, source: str, use_wildcard: bool = True
                         ) -> list[tuple[str, dict[str, Any]]]:
    """The parameters a ``ros2 param dump`` file sets, as (name, ParameterValue wire form),
    in the order ``ros2 param load`` sets them: the ``/**`` entry first (only with
    ``use_wildcard``), then every node's entry in file order, later names overriding.

    Raises:
        ParameterFileError: the text is not such a file (the text names ``source``, the node
            entry and the parameter at fault).
    """
    import yaml

    try:
        document = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        at = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ParameterFileError(f"{source} is not valid YAML{at}: {problem}") from None
    if not isinstance(document, Mapping) or not document:
        raise ParameterFileError(f"{source}: expected a mapping of node names to "
                                 "'ros__parameters' tables (the format of 'param dump')")
    keys = [WILDCARD] if use_wildcard and WILDCARD in document else []
    keys += [str(k) for k in document if k != WILDCARD]
    if not keys:
        raise ParameterFileError(f"{source}: holds only the '{WILDCARD}' entry and "
                                 "--no-use-wildcard leaves it out")
    merged: dict[str, Any] = {}
    for key in keys:
        entry = document[key]
        if not isinstance(entry, Mapping) or not isinstance(entry.get("ros__parameters"),
                                                             Mapping):
            raise ParameterFileError(f"{source}: the entry {key!r} has no 'ros__parameters' "
                                     "mapping (not a ROS parameter file)")
        merged.update(_flatten("", entry["ros__parameters"]))
    try:
        return [(name, typed_value(value, f"{source}: parameter {name}"))
                for name, value in merged.items()]
    except ArgumentError as exc:
        raise ParameterFileError(str(exc)) from None
