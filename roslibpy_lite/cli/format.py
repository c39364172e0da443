"""Text in and out for the command-line tool: YAML/JSON arguments, YAML-like message output.

Arguments are parsed with PyYAML when it is installed (``pip install
roslibpy-lite[cli]``), else as JSON only. Output never needs PyYAML: a small
emitter writes messages the way ``ros2 topic echo`` does (block style, fields
in message order, strings in single quotes, documents separated by ``---``).
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from typing import Any

__all__ = ["ArgumentError", "have_yaml", "parse_values", "to_yaml"]


class ArgumentError(ValueError):
    """A command-line value could not be read (the text says what and where)."""


def have_yaml() -> bool:
    """True when PyYAML is installed (YAML arguments accepted, not only JSON)."""
    try:
        import yaml  # noqa: F401
    except ImportError:
        return False
    return True


def parse_values(text: str | None, what: str = "VALUES") -> dict[str, Any]:
    """Parse a mapping given on the command line in YAML (``{x: 2.5}``) or JSON.

    An empty or missing text is ``{}``.

    Raises:
        ArgumentError: the text is not valid YAML/JSON, or not a mapping.
    """
    if text is None or not text.strip():
        return {}
    try:
        import yaml
    except ImportError:
        yaml = None  # type: ignore[assignment]
    value: Any
    if yaml is not None:
        try:
            value = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            mark = getattr(exc, "problem_mark", None)
            where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
            problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
            raise ArgumentError(f"{what} is not valid YAML{where}: {problem}") from None
    else:
        try:
            value = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ArgumentError(
                f"{what} is not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg}); "
                "PyYAML is not installed, so only JSON is accepted "
                "(for YAML: pip install pyyaml, or install the wheel with its [cli] extra)"
            ) from None
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise ArgumentError(
            f"{what} must be a mapping such as '{{x: 2.5, y: 4.0}}', "
            f"got {type(value).__name__} {text.strip()[:40]!r}"
        )
    return {str(k): v for k, v in value.items()}


_PLAIN = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")  # ROS field names stay plain
_RESERVED = frozenset({"true", "false", "yes", "no", "on", "off", "null", "~"})


_ESCAPES = {"\\": "\\\\", '"': '\\"', "\n": "\\n", "\t": "\\t", "\r": "\\r"}


def _double_quoted(text: str) -> str:
    """A YAML double-quoted string; anything not printable is escaped by code point."""
    out = []
    for ch in text:
        if ch in _ESCAPES:
            out.append(_ESCAPES[ch])
        elif ch.isprintable():
            out.append(ch)
        elif ord(ch) <= 0xFF:
            out.append(f"\\x{ord(ch):02x}")
        elif ord(ch) <= 0xFFFF:
            out.append(f"\\u{ord(ch):04x}")
        else:
            out.append(f"\\U{ord(ch):08x}")
    return '"' + "".join(out) + '"'


def _key(key: str) -> str:
    return key if _PLAIN.fullmatch(key) and key.lower() not in _RESERVED else _double_quoted(key)


def _scalar(value: Any) -> str:
    if value is None:
        return "null"
    if value is True:
        return "true"
    if value is False:
        return "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return ".nan"
        if math.isinf(value):
            return ".inf" if value > 0 else "-.inf"
        text = repr(value)
        if "." not in text:  # YAML 1.1 floats need a dot: 1e+20 -> 1.0e+20
            mantissa, _, exponent = text.partition("e")
            text = f"{mantissa}.0e{exponent}" if exponent else f"{mantissa}.0"
        return text
    text = str(value)
    if text.isprintable():
        return "'" + text.replace("'", "''") + "'"
    return _double_quoted(text)


def _emit(value: Any, indent: int, lines: list[str], no_arr: bool) -> None:
    pad = "  " * indent
    if isinstance(value, Mapping):
        for k, v in value.items():
            key = _key(str(k))
            if isinstance(v, Mapping) and v:
                lines.append(f"{pad}{key}:")
                _emit(v, indent + 1, lines, no_arr)
            elif isinstance(v, list | tuple) and v:
                if no_arr:
                    lines.append(f"{pad}{key}: '<sequence, length: {len(v)}>'")
                else:
                    lines.append(f"{pad}{key}:")
                    _emit_list(v, indent, lines, no_arr)
            else:
                lines.append(f"{pad}{key}: {_inline(v)}")
    else:
        lines.append(pad + _inline(value))


def _emit_list(items: list[Any] | tuple[Any, ...], indent: int, lines: list[str],
               no_arr: bool) -> None:
    pad = "  " * indent
    for item in items:
        if isinstance(item, Mapping) and item:
            sub: list[str] = []
            _emit(item, indent + 1, sub, no_arr)
            first = sub[0][len(pad) + 2:]
            lines.append(f"{pad}- {first}")
            lines.extend(sub[1:])
        elif isinstance(item, list | tuple) and item:
            sub = []
            _emit_list(item, indent + 1, sub, no_arr)
            lines.append(f"{pad}-")
            lines.extend(sub)
        else:
            lines.append(f"{pad}- {_inline(item)}")


def _inline(value: Any) -> str:
    if isinstance(value, Mapping):
        return "{}"
    if isinstance(value, list | tuple):
        return "[]"
    return _scalar(value)


def to_yaml(value: Any, *, no_arr: bool = False) -> str:
    """``value`` as block-style YAML (no trailing newline); ``no_arr`` shortens sequences."""
    lines: list[str] = []
    _emit(value, 0, lines, no_arr)
    return "\n".join(lines) if lines else "{}"
