"""rosapi typedefs of a message type and its nested types, from any ROS side's classes.

A typedef is what rosapi's ``message_details`` (and the service and action variants)
answer: field names, types, array lengths, example values and constants. The rclpy Graph
(:mod:`bridge_server.rclpy_graph.introspection`) and the in-memory one
(:mod:`rosbridge_core.memory.graph`) both build them here, from a class's
``get_fields_and_field_types()`` (rclpy's spelling, which ``msgs`` classes share) and
what each side says of constants and nested types.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any

__all__ = ["msgs_constants", "msgs_typedefs", "typedefs_of"]

_SEQ = re.compile(r"sequence<([^,>]+)(?:,\s*(\d+))?>\Z")
_ARR = re.compile(r"(.+)\[(\d+)\]\Z")
_EXAMPLES = {"boolean": "False", "string": "", "wstring": "", "float": "0.0", "double": "0.0"}


def _split_field_type(spec: str) -> tuple[str, int]:
    """Base type and array length: ``sequence<double>`` -> (double, 0), ``double[36]`` ->
    (double, 36), ``int32`` -> (int32, -1)."""
    m = _SEQ.match(spec)
    if m:
        return m.group(1).strip(), 0
    m = _ARR.match(spec)
    if m:
        return m.group(1), int(m.group(2))
    return spec, -1


def _full_type(base: str) -> str:
    if "/" in base:
        pkg, _, name = base.rpartition("/")
        return f"{pkg.split('/')[0]}/msg/{name}"
    if base.startswith(("string<", "wstring<")):
        return base.split("<")[0]
    return base


def typedefs_of(
    cls: Any, name: str, *, constants: Callable[[Any], dict[str, Any]],
    resolve: Callable[[str], Any], name_of: Callable[[Any], str],
) -> list[dict[str, Any]]:
    """The typedef of ``cls`` (named ``name``), then those of every nested type, each once.

    ``constants(cls)`` gives a class's constants by name, ``resolve`` a nested
    ``pkg/msg/Name``'s class, ``name_of`` a class's canonical name.
    """
    out: list[dict[str, Any]] = []
    seen: set[Any] = set()
    todo: list[tuple[Any, str]] = [(cls, name)]
    while todo:
        current, current_name = todo.pop(0)
        if current in seen:
            continue
        seen.add(current)
        fieldnames, fieldtypes, arraylens, examples = [], [], [], []
        for field_name, spec in current.get_fields_and_field_types().items():
            base, arraylen = _split_field_type(spec)
            full = _full_type(base)
            fieldnames.append(field_name)
            fieldtypes.append(full)
            arraylens.append(arraylen)
            if arraylen >= 0:
                examples.append("[]")
            elif "/" in full:
                examples.append("{}")
            else:
                examples.append(_EXAMPLES.get(full, "0"))
            if "/" in full:
                nested = resolve(full)
                if nested not in seen:
                    todo.append((nested, name_of(nested)))
        consts = constants(current)
        out.append({
            "type": current_name,
            "fieldnames": fieldnames,
            "fieldtypes": fieldtypes,
            "fieldarraylen": arraylens,
            "examples": examples,
            "constnames": list(consts),
            "constvalues": [str(v) for v in consts.values()],
        })
    return out


def msgs_constants(cls: Any) -> dict[str, Any]:
    """A ``msgs`` class's constants by name, in definition order."""
    from msgs.parser import parse_message

    package, _, short = cls._type.split("/")
    spec = parse_message(cls._definition, package, short)
    return {c.name: getattr(cls, c.name) for c in spec.constants}


def msgs_typedefs(cls: Any, name: str) -> list[dict[str, Any]]:
    """:func:`typedefs_of` a ``msgs`` message class."""
    return typedefs_of(cls, name, constants=msgs_constants, resolve=cls._lookup,
                       name_of=lambda c: c._type)
