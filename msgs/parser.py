"""A pure-Python parser for ROS 2 interface definitions (``.msg``, ``.srv``, ``.action``).

No ROS import: the parser reads text and returns a small frozen model::

    MessageSpec(package, name, kind, fields=(FieldSpec...), constants=(ConstantSpec...))
    ServiceSpec(package, name, request: MessageSpec, response: MessageSpec)
    ActionSpec(package, name, goal, result, feedback: MessageSpec)

Grammar covered (the rosidl ``.msg`` dialect): every primitive type (``bool byte char
float32 float64 int8..int64 uint8..uint64 string wstring``), bounded strings
(``string<=10``), fixed arrays ``T[3]``, bounded sequences ``T[<=5]``, unbounded
sequences ``T[]``, default values (scalars, ``[1, 2]`` arrays, quoted or bare strings),
constants (``int32 X=5``, ``string S="x"``), ``#`` comments, and nested types written
``Name`` (same package), ``pkg/Name`` or ``pkg/msg/Name``.

Every malformed definition raises :class:`DefinitionError`, whose message names the
file, the line and the reason.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from ._primitives import FLOAT32_MAX, INTEGER_RANGES

__all__ = [
    "FLOAT32_MAX",
    "FLOAT_TYPES",
    "INTEGER_RANGES",
    "PRIMITIVE_TYPES",
    "STRING_TYPES",
    "ActionSpec",
    "ConstantSpec",
    "DefinitionError",
    "FieldSpec",
    "InterfaceSpec",
    "MessageSpec",
    "ServiceSpec",
    "TypeRef",
    "parse_action",
    "parse_file",
    "parse_message",
    "parse_service",
]

FLOAT_TYPES = frozenset({"float32", "float64"})
STRING_TYPES = frozenset({"string", "wstring"})
PRIMITIVE_TYPES = frozenset({"bool", *INTEGER_RANGES, *FLOAT_TYPES, *STRING_TYPES})

# The names rclpy's get_fields_and_field_types() uses for the .msg primitive names.
_IDL_NAMES = {
    "bool": "boolean",
    "byte": "octet",
    "char": "uint8",
    "float32": "float",
    "float64": "double",
}

_PACKAGE_RE = re.compile(r"^[a-z][a-z0-9_]*$")
_TYPE_NAME_RE = re.compile(r"^[A-Z][A-Za-z0-9]*$")
_FIELD_NAME_RE = re.compile(r"^(?!.*__)(?!.*_$)[a-z][a-z0-9_]*$")
_CONSTANT_NAME_RE = re.compile(r"^(?!.*__)(?!.*_$)[A-Z][A-Z0-9_]*$")
_LINE_RE = re.compile(r"^(?P<type>\S+)\s+(?P<name>[A-Za-z0-9_]+)(?P<rest>.*)$")
_ARRAY_RE = re.compile(r"^(?P<base>[^\[\]]+)\[(?P<bound><=)?(?P<size>[^\]]*)\]$")
_STRING_BOUND_RE = re.compile(r"^(?P<base>w?string)<=(?P<size>.*)$")

SCALAR_VALUE = bool | int | float | str
DefaultValue = SCALAR_VALUE | tuple[SCALAR_VALUE, ...]


class DefinitionError(ValueError):
    """A definition file is malformed; the message names file, line and reason."""

    def __init__(self, file: str, line: int, reason: str) -> None:
        self.file = file
        self.line = line
        self.reason = reason
        super().__init__(f"{file}:{line}: {reason}")


@dataclass(frozen=True)
class TypeRef:
    """The type of one field or constant.

    ``name`` is a primitive name (``int32``, ``string`` ...) or a message name; ``package``
    is set for message types only. ``array`` is ``None`` for a scalar, else ``"fixed"``
    (``T[n]``), ``"bounded"`` (``T[<=n]``) or ``"unbounded"`` (``T[]``) with ``array_size``
    the length or bound. ``string_bound`` is the ``N`` of ``string<=N``.
    """

    name: str
    package: str | None = None
    string_bound: int | None = None
    array: Literal["fixed", "bounded", "unbounded"] | None = None
    array_size: int | None = None

    @property
    def is_primitive(self) -> bool:
        """True for the built-in primitive types (including strings)."""
        return self.package is None

    @property
    def is_array(self) -> bool:
        """True for fixed arrays and bounded or unbounded sequences."""
        return self.array is not None

    @property
    def element(self) -> TypeRef:
        """The element type (the type itself for a scalar)."""
        return TypeRef(self.name, self.package, self.string_bound)

    @property
    def message_type(self) -> str:
        """``pkg/msg/Name`` of a nested message type (ValueError for primitives)."""
        if self.package is None:
            raise ValueError(f"{self.name} is a primitive type")
        return f"{self.package}/msg/{self.name}"

    def idl_name(self) -> str:
        """The spelling rclpy's ``get_fields_and_field_types()`` uses for this type.

        For example ``double``, ``string<10>``, ``std_msgs/Header``, ``int32[3]``,
        ``sequence<octet, 5>``, ``sequence<geometry_msgs/Point>``.
        """
        if self.package is not None:
            base = f"{self.package}/{self.name}"
        else:
            base = _IDL_NAMES.get(self.name, self.name)
            if self.string_bound is not None:
                base = f"{base}<{self.string_bound}>"
        if self.array == "fixed":
            return f"{base}[{self.array_size}]"
        if self.array == "bounded":
            return f"sequence<{base}, {self.array_size}>"
        if self.array == "unbounded":
            return f"sequence<{base}>"
        return base

    def __str__(self) -> str:
        """The ``.msg`` spelling, e.g. ``string<=5[<=3]`` or ``std_msgs/Header[]``."""
        base = f"{self.package}/{self.name}" if self.package is not None else self.name
        if self.string_bound is not None:
            base = f"{base}<={self.string_bound}"
        if self.array == "fixed":
            return f"{base}[{self.array_size}]"
        if self.array == "bounded":
            return f"{base}[<={self.array_size}]"
        if self.array == "unbounded":
            return f"{base}[]"
        return base


@dataclass(frozen=True)
class FieldSpec:
    """One field: name, type, optional default (a tuple for arrays) and source line."""

    name: str
    type: TypeRef
    default: DefaultValue | None = None
    line: int = 0


@dataclass(frozen=True)
class ConstantSpec:
    """One constant: name, primitive scalar type and value."""

    name: str
    type: TypeRef
    value: SCALAR_VALUE
    line: int = 0


@dataclass(frozen=True)
class MessageSpec:
    """A message (or one part of a service or action).

    ``kind`` is the interface kind the message belongs to (``msg``, ``srv``, ``action``);
    ``name`` is e.g. ``String``, ``MultFloats_Request`` or ``Fibonacci_Goal``;
    ``source`` is the definition text of this part.
    """

    package: str
    name: str
    fields: tuple[FieldSpec, ...]
    constants: tuple[ConstantSpec, ...]
    source: str
    kind: Literal["msg", "srv", "action"] = "msg"
    file: str = "<string>"

    @property
    def type_name(self) -> str:
        """The full type name, e.g. ``std_msgs/msg/String``."""
        return f"{self.package}/{self.kind}/{self.name}"


@dataclass(frozen=True)
class ServiceSpec:
    """A service: request and response messages."""

    package: str
    name: str
    request: MessageSpec
    response: MessageSpec
    source: str
    file: str = "<string>"

    @property
    def type_name(self) -> str:
        """The full type name, e.g. ``std_srvs/srv/SetBool``."""
        return f"{self.package}/srv/{self.name}"


@dataclass(frozen=True)
class ActionSpec:
    """An action: goal, result and feedback messages."""

    package: str
    name: str
    goal: MessageSpec
    result: MessageSpec
    feedback: MessageSpec
    source: str
    file: str = "<string>"

    @property
    def type_name(self) -> str:
        """The full type name, e.g. ``test_msgs/action/Fibonacci``."""
        return f"{self.package}/action/{self.name}"


InterfaceSpec = MessageSpec | ServiceSpec | ActionSpec


def _strip_comment(line: str) -> str:
    """Remove a ``#`` comment, ignoring ``#`` inside quoted strings."""
    quote: str | None = None
    escaped = False
    for i, ch in enumerate(line):
        if escaped:
            escaped = False
        elif quote is not None:
            if ch == "\\":
                escaped = True
            elif ch == quote:
                quote = None
        elif ch in "\"'":
            quote = ch
        elif ch == "#":
            return line[:i]
    return line


class _LineParser:
    """Parses the lines of one message part; knows file and line for errors."""

    def __init__(self, package: str, file: str) -> None:
        self.package = package
        self.file = file

    def error(self, line: int, reason: str) -> DefinitionError:
        return DefinitionError(self.file, line, reason)

    def parse_size(self, text: str, line: int, what: str) -> int:
        if not text.isdigit():
            raise self.error(line, f"{what} must be a positive integer, got {text!r}")
        size = int(text)
        if size <= 0:
            raise self.error(line, f"{what} must be a positive integer, got {size}")
        return size

    def parse_type(self, text: str, line: int) -> TypeRef:
        array: Literal["fixed", "bounded", "unbounded"] | None = None
        array_size: int | None = None
        base = text
        match = _ARRAY_RE.match(text)
        if match is not None:
            base = match["base"]
            if match["bound"]:
                array = "bounded"
                array_size = self.parse_size(match["size"], line, "sequence bound")
            elif match["size"] == "":
                array = "unbounded"
            else:
                array = "fixed"
                array_size = self.parse_size(match["size"], line, "array size")
        elif "[" in text or "]" in text:
            raise self.error(line, f"malformed array type {text!r}")
        string_bound: int | None = None
        bound_match = _STRING_BOUND_RE.match(base)
        if bound_match is not None:
            base = bound_match["base"]
            string_bound = self.parse_size(bound_match["size"], line, "string bound")
        elif "<" in base or ">" in base or "=" in base:
            raise self.error(line, f"malformed type {text!r} (only strings take a <=N bound)")
        if base in PRIMITIVE_TYPES:
            return TypeRef(base, None, string_bound, array, array_size)
        parts = base.split("/")
        if len(parts) == 3 and parts[1] == "msg":
            parts = [parts[0], parts[2]]
        if len(parts) == 1:
            package, name = self.package, parts[0]
        elif len(parts) == 2:
            package, name = parts
            if not _PACKAGE_RE.match(package):
                raise self.error(line, f"invalid package name {package!r} in type {text!r}")
        else:
            raise self.error(line, f"invalid type {text!r}")
        if not _TYPE_NAME_RE.match(name):
            raise self.error(line, f"unknown type {base!r}")
        return TypeRef(name, package, None, array, array_size)

    def parse_scalar(self, type_: TypeRef, text: str, line: int) -> SCALAR_VALUE:
        name = type_.name
        if name == "bool":
            lowered = text.lower()
            if lowered in ("true", "1"):
                return True
            if lowered in ("false", "0"):
                return False
            raise self.error(line, f"invalid bool value {text!r} (expected true or false)")
        if name in INTEGER_RANGES:
            try:
                value = int(text, 0) if text.lower().startswith(("0x", "-0x")) else int(text)
            except ValueError:
                raise self.error(line, f"invalid {name} value {text!r}") from None
            low, high = INTEGER_RANGES[name]
            if not low <= value <= high:
                raise self.error(line, f"{name} value {value} out of range [{low}, {high}]")
            return value
        if name in FLOAT_TYPES:
            try:
                fvalue = float(text)
            except ValueError:
                raise self.error(line, f"invalid {name} value {text!r}") from None
            if name == "float32" and math.isfinite(fvalue) and abs(fvalue) > FLOAT32_MAX:
                raise self.error(line, f"float32 value {text} out of range")
            return fvalue
        # string / wstring
        value_s = _unquote(text)
        if value_s is None:
            raise self.error(line, f"unterminated string literal {text!r}")
        if type_.string_bound is not None and len(value_s) > type_.string_bound:
            raise self.error(
                line, f"string value longer than its bound {type_.string_bound}: {value_s!r}"
            )
        return value_s

    def parse_array_default(self, type_: TypeRef, text: str, line: int) -> tuple[SCALAR_VALUE, ...]:
        if not (text.startswith("[") and text.endswith("]")):
            raise self.error(line, f"array default must be written [a, b, ...], got {text!r}")
        items = _split_items(text[1:-1])
        if items is None:
            raise self.error(line, f"malformed array default {text!r}")
        element = type_.element
        values = tuple(self.parse_scalar(element, item, line) for item in items)
        if type_.array == "fixed" and len(values) != type_.array_size:
            raise self.error(
                line, f"array default has {len(values)} values, the array has {type_.array_size}"
            )
        if type_.array == "bounded" and len(values) > (type_.array_size or 0):
            raise self.error(
                line,
                f"array default has {len(values)} values, more than the bound {type_.array_size}",
            )
        return values


def _unquote(text: str) -> str | None:
    """Strip and unescape quotes of a string literal; bare text is taken as is."""
    if not text or text[0] not in "\"'":
        return text
    quote = text[0]
    if len(text) < 2 or text[-1] != quote:
        return None
    out: list[str] = []
    body = text[1:-1]
    i = 0
    while i < len(body):
        ch = body[i]
        if ch == "\\" and i + 1 < len(body):
            nxt = body[i + 1]
            out.append({"n": "\n", "t": "\t", "\\": "\\", "'": "'", '"': '"'}.get(nxt, "\\" + nxt))
            i += 2
            continue
        if ch == quote:
            return None
        out.append(ch)
        i += 1
    return "".join(out)


def _split_items(body: str) -> list[str] | None:
    """Split ``a, "b,c", d`` on commas outside quotes; ``[]`` gives no items."""
    if not body.strip():
        return []
    items: list[str] = []
    current: list[str] = []
    quote: str | None = None
    escaped = False
    for ch in body:
        if escaped:
            escaped = False
        elif quote is not None:
            if ch == "\\":
                escaped = True
            elif ch == quote:
                quote = None
        elif ch in "\"'":
            quote = ch
        elif ch == ",":
            items.append("".join(current).strip())
            current = []
            continue
        current.append(ch)
    if quote is not None:
        return None
    items.append("".join(current).strip())
    if any(not item for item in items):
        return None
    return items


def parse_message(
    text: str,
    package: str,
    name: str,
    *,
    file: str = "<string>",
    kind: Literal["msg", "srv", "action"] = "msg",
    first_line: int = 1,
) -> MessageSpec:
    """Parse one ``.msg`` text (or one part of a ``.srv``/``.action``).

    ``first_line`` is the line number of the text's first line in ``file``, so that
    errors in the second part of a service name the right line.
    """
    if not _PACKAGE_RE.match(package):
        raise DefinitionError(file, first_line, f"invalid package name {package!r}")
    if not re.match(r"^[A-Z][A-Za-z0-9]*(_[A-Z][A-Za-z0-9]*)?$", name):
        raise DefinitionError(file, first_line, f"invalid type name {name!r}")
    parser = _LineParser(package, file)
    fields: list[FieldSpec] = []
    constants: list[ConstantSpec] = []
    seen: set[str] = set()
    for offset, raw in enumerate(text.splitlines()):
        lineno = first_line + offset
        line = _strip_comment(raw).strip()
        if not line:
            continue
        match = _LINE_RE.match(line)
        if match is None:
            raise parser.error(
                lineno, f"expected 'TYPE NAME [DEFAULT]' or 'TYPE NAME=VALUE': {line!r}"
            )
        type_text, field_name, rest = match["type"], match["name"], match["rest"]
        type_ = parser.parse_type(type_text, lineno)
        stripped = rest.strip()
        if stripped.startswith("="):
            if not _CONSTANT_NAME_RE.match(field_name):
                raise parser.error(lineno, f"invalid constant name {field_name!r} (use UPPER_CASE)")
            if not type_.is_primitive or type_.is_array:
                raise parser.error(
                    lineno, f"constant {field_name} must have a primitive scalar type"
                )
            value_text = stripped[1:].strip()
            if not value_text:
                raise parser.error(lineno, f"constant {field_name} has no value")
            if field_name in seen:
                raise parser.error(lineno, f"duplicate name {field_name!r}")
            seen.add(field_name)
            value = parser.parse_scalar(type_, value_text, lineno)
            constants.append(ConstantSpec(field_name, type_, value, lineno))
            continue
        if rest and not rest[0].isspace():
            raise parser.error(lineno, f"invalid field name in {line!r}")
        if not _FIELD_NAME_RE.match(field_name):
            raise parser.error(
                lineno,
                f"invalid field name {field_name!r} (lower_case letters, digits and single "
                "underscores, starting with a letter)",
            )
        if field_name in seen:
            raise parser.error(lineno, f"duplicate name {field_name!r}")
        seen.add(field_name)
        default: DefaultValue | None = None
        if stripped:
            if not type_.is_primitive:
                raise parser.error(
                    lineno, f"field {field_name} of message type {type_} cannot have a default"
                )
            if type_.is_array:
                default = parser.parse_array_default(type_, stripped, lineno)
            else:
                default = parser.parse_scalar(type_, stripped, lineno)
        fields.append(FieldSpec(field_name, type_, default, lineno))
    return MessageSpec(package, name, tuple(fields), tuple(constants), text, kind, file)


def _split_parts(text: str, count: int, file: str) -> list[tuple[str, int]]:
    """Split at lines that are exactly ``---``; return (text, first line) per part."""
    parts: list[tuple[str, int]] = []
    current: list[str] = []
    start = 1
    for lineno, raw in enumerate(text.splitlines(), start=1):
        if raw.strip() == "---":
            parts.append(("\n".join(current) + ("\n" if current else ""), start))
            current = []
            start = lineno + 1
        else:
            current.append(raw)
    parts.append(("\n".join(current) + ("\n" if current else ""), start))
    if len(parts) != count:
        raise DefinitionError(
            file,
            len(text.splitlines()) or 1,
            f"expected {count - 1} '---' separator line(s), found {len(parts) - 1}",
        )
    return parts


def parse_service(text: str, package: str, name: str, *, file: str = "<string>") -> ServiceSpec:
    """Parse a ``.srv`` text: request, ``---``, response."""
    (req, req_line), (res, res_line) = _split_parts(text, 2, file)
    request = parse_message(
        req, package, f"{name}_Request", file=file, kind="srv", first_line=req_line
    )
    response = parse_message(
        res, package, f"{name}_Response", file=file, kind="srv", first_line=res_line
    )
    return ServiceSpec(package, name, request, response, text, file)


def parse_action(text: str, package: str, name: str, *, file: str = "<string>") -> ActionSpec:
    """Parse an ``.action`` text: goal, ``---``, result, ``---``, feedback."""
    parts = _split_parts(text, 3, file)
    goal, result, feedback = (
        parse_message(part, package, f"{name}_{suffix}", file=file, kind="action", first_line=ln)
        for (part, ln), suffix in zip(parts, ("Goal", "Result", "Feedback"), strict=True)
    )
    return ActionSpec(package, name, goal, result, feedback, text, file)


def parse_file(path: str | Path, package: str | None = None) -> InterfaceSpec:
    """Parse a definition file; the kind comes from the suffix.

    The package defaults to the name of the directory above ``msg/``, ``srv/`` or
    ``action/`` (the ROS layout ``<pkg>/msg/Name.msg``).
    """
    path = Path(path)
    if package is None:
        package = path.parent.parent.name
    file = str(path)
    name = path.stem
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise DefinitionError(file, 1, f"not UTF-8 text: {exc}") from None
    if not _TYPE_NAME_RE.match(name):
        raise DefinitionError(file, 1, f"invalid type name {name!r} (from the file name)")
    if path.suffix == ".msg":
        return parse_message(text, package, name, file=file)
    if path.suffix == ".srv":
        return parse_service(text, package, name, file=file)
    if path.suffix == ".action":
        return parse_action(text, package, name, file=file)
    raise DefinitionError(file, 1, f"unknown definition suffix {path.suffix!r}")
