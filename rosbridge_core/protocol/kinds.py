"""What a field of an op may hold (:class:`_Kind`: a description for errors, a check, a
normaliser), the kinds the ops' fields name in their annotations (``Annotated[str, _NAME]``),
how a wrong value is described in a parse error (:func:`_describe`), and each op class's
fields with their kinds (:func:`_rules_of`).

Private to the protocol core: :mod:`rosbridge_core.protocol.ops` declares the ops with these.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping
from dataclasses import MISSING, fields
from typing import Any, NamedTuple, TypeAlias, get_type_hints

__all__: list[str] = []


class _Kind(NamedTuple):
    """What a field of an op may hold: its description in errors, a check, a normaliser.
    Each field names its kind in its annotation (``Annotated[str, _NAME]``); a field with
    no default is required."""

    expected: str
    check: Callable[[Any], bool]
    normalise: Callable[[Any], Any]


def _same(value: Any) -> Any:
    return value


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value: Any) -> bool:
    return (isinstance(value, int | float)) and not isinstance(value, bool)


def _as_ms(value: Any) -> int:
    return int(value)


_STR = _Kind("a string", lambda v: isinstance(v, str), _same)
_NAME = _Kind("a non-empty string", lambda v: isinstance(v, str) and v != "", _same)
_ID = _Kind("a string or an integer", lambda v: isinstance(v, str) or _is_int(v), _same)
_BOOL = _Kind("true or false", lambda v: isinstance(v, bool), _same)
_INT = _Kind("an integer", _is_int, _same)
_COUNT = _Kind("an integer >= 0", lambda v: _is_int(v) and v >= 0, _same)
_SIZE = _Kind("an integer > 0", lambda v: _is_int(v) and v > 0, _same)
_MS = _Kind("a number of milliseconds >= 0", lambda v: _is_number(v) and v >= 0, _as_ms)
_SECONDS = _Kind(
    "a number of seconds > 0",
    lambda v: _is_number(v) and v > 0 and math.isfinite(v),
    float,
)
_OBJECT = _Kind("an object", lambda v: isinstance(v, Mapping), _same)
_ARGS = _Kind("an object or a list", lambda v: isinstance(v, Mapping | list), _same)
_VALUES = _Kind("an object or a string", lambda v: isinstance(v, Mapping | str), _same)

_ANY = _Kind("anything", lambda v: True, _same)


def _kind_of(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, int | float):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, Mapping):
        return "an object"
    return type(value).__name__


def _describe(value: Any) -> str:
    if isinstance(value, str | int | float | bool):
        text = json.dumps(value)
        return f"{_kind_of(value)} {text if len(text) <= 40 else text[:37] + '...'}"
    return _kind_of(value)


# {field: (kind, required)} of an op class, read from its annotations
_Rules: TypeAlias = dict[str, tuple[_Kind, bool]]


def _rules_of(cls: type[Any]) -> _Rules:
    hints = get_type_hints(cls, include_extras=True)
    rules: _Rules = {}
    for f in fields(cls):
        kinds = [m for m in getattr(hints[f.name], "__metadata__", ()) if isinstance(m, _Kind)]
        if len(kinds) != 1:
            raise TypeError(f"{cls.__name__}.{f.name}: annotate it with its kind, once")
        rules[f.name] = (kinds[0], f.default is MISSING and f.default_factory is MISSING)
    return rules
