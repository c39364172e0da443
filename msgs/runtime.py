"""The base of the generated message classes, and type lookup by name.

Contract (what the client relies on):

* :class:`Message` is the base of every generated message class. The classes are
  mutable, slotted, keyword-only dataclasses (``String(data="hi")``; like rclpy, fields
  may be reassigned). Building one checks each field's kind, range and length (an
  unknown field is a ``TypeError``, a value that does not fit a :class:`ValidationError`
  naming the field, the expected type and the message type); a nested message was
  checked when it was built. Fields reassigned later are checked by ``validate()``.
  Class attributes:

  - ``_type``: ``"pkg/msg/Name"``; service parts ``"pkg/srv/Name_Request"`` /
    ``"pkg/srv/Name_Response"``; action parts ``"pkg/action/Name_Goal"``,
    ``"_Result"``, ``"_Feedback"``.
  - ``_definition``: the definition text of the type (of this part, for services and
    actions).
  - ``_fields_and_types``: field name -> type string, in rclpy's
    ``get_fields_and_field_types()`` spelling: ``boolean``, ``octet``, ``uint8``, ``float``
    (float32), ``double`` (float64), ``int32``, ``string``, ``string<10>`` (bounded),
    ``wstring``, ``std_msgs/Header`` (nested), ``int32[3]`` (fixed array),
    ``sequence<int32, 5>`` (bounded), ``sequence<int32>`` (unbounded).

  Python-side field values: ``uint8``/``char`` arrays (fixed or not) are ``bytes``;
  every other array is a ``list``; strings ``str``; integers (``byte`` too) ``int``;
  floats ``float``; nested messages instances of their class.

* ``msg.to_json()`` gives the rosbridge JSON form: ``uint8[]``/``char[]`` as a base64
  string, NaN and +-Inf floats as ``None``, nested messages as dicts (Time and Duration
  are plain ``{"sec", "nanosec"}`` messages). It does not validate; call
  ``msg.validate()`` first when the values may be wrong.
* ``Cls.from_json(data)`` accepts the wire form from JSON or CBOR: ``uint8[]`` as base64
  string, bytes-like or list of ints; numeric arrays as list, tuple, ``array.array`` or
  memoryview; ``None`` for a float means NaN. Missing fields keep their defaults. An
  unknown field, a value of the wrong kind or out of range raises
  :class:`ValidationError`, whose message names the field path (``pose.position.x``)
  and the expected type.
* :class:`Service` (``Request``, ``Response``) and :class:`Action` (``Goal``,
  ``Result``, ``Feedback``) are namespaces, not instantiable.
* :func:`lookup` finds a type by name in either spelling (``std_msgs/String`` or
  ``std_msgs/msg/String``), importing its generated module on first use.
"""

from __future__ import annotations

import array
import base64
import binascii
import dataclasses as _dc
import html
import importlib
import keyword
import math
import re
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, ClassVar, Self

from ._primitives import FLOAT32_MAX, INTEGER_RANGES, SIZED_INTEGER_RANGES

__all__ = [
    "Action",
    "Find",
    "Message",
    "Service",
    "UnknownTypeError",
    "ValidationError",
    "available_packages",
    "available_types",
    "lookup",
    "lookup_action",
    "lookup_generated",
    "lookup_message",
    "lookup_service",
    "register",
]

_INT_RANGES = {"octet": INTEGER_RANGES["byte"], **SIZED_INTEGER_RANGES}
"""The integer types by rclpy's names for them."""
# The .msg spelling of rclpy's type names, for error messages.
_MSG_NAMES = {"boolean": "bool", "octet": "byte", "float": "float32", "double": "float64"}
_REPR_LIMIT = 40
_MISSING = object()


class ValidationError(ValueError):
    """A value does not fit its field: names the field ``path`` and the ``expected`` type."""

    def __init__(self, path: str, expected: str, problem: str) -> None:
        self.path = path
        self.expected = expected
        self.problem = problem
        where = path or "<message>"
        super().__init__(f"{where}: expected {expected}, {problem}")

    def _under(self, step: str) -> ValidationError:
        """The same error seen from one level up: ``step`` is ``name`` or ``[i]``."""
        if not self.path:
            path = step
        elif self.path.startswith("["):
            path = step + self.path
        else:
            path = f"{step}.{self.path}"
        return ValidationError(path, self.expected, self.problem)


class UnknownTypeError(LookupError):
    """No generated interface type has this name."""

    def __init__(self, type_name: str, reason: str) -> None:
        self.type_name = type_name
        super().__init__(f"unknown interface type {type_name!r}: {reason}")

    def __str__(self) -> str:
        return str(self.args[0])


def _describe(value: object) -> str:
    """A short description of a bad value for error messages (type and a clipped repr).

    A type from outside the builtins is named with its module (``numpy.float32``), so it
    never reads as the field's own type name."""
    text = repr(value)
    if len(text) > _REPR_LIMIT:
        text = text[: _REPR_LIMIT - 3] + "..."
    kind = type(value)
    name = kind.__name__ if kind.__module__ == "builtins" else f"{kind.__module__}.{kind.__name__}"
    return f"got {name} {text}"


def _scalar(value: Any) -> Any:
    """A numpy scalar or 0-d array as its Python number or bool (``value.item()``); any
    other value as it is. Only on the slow path of the checks: numpy is not imported."""
    if getattr(value, "ndim", None) == 0 and type(value).__module__ == "numpy":
        return value.item()
    return value


# A converter checks one value and returns its Python-side form. It raises
# ValidationError with a path relative to the value; callers prefix their step
# when the error passes through them, so no path is built unless there is an error.
_Conv = Callable[[Any], Any]
# An encoder turns a Python-side value into its JSON form.
_Enc = Callable[[Any], Any]
_Find = Callable[[str], "type[Message]"]


def _bool_conv(value: Any) -> bool:
    if value is True or value is False:
        return bool(value)
    plain = _scalar(value)
    if plain is True or plain is False:
        return plain
    raise ValidationError("", "bool", _describe(value))


def _int_conv(idl: str) -> _Conv:
    low, high = _INT_RANGES[idl]
    expected = _MSG_NAMES.get(idl, idl)

    def conv(value: Any) -> int:
        if type(value) is not int:
            plain = _scalar(value)
            if (isinstance(plain, float) and plain.is_integer()) or (
                isinstance(plain, int) and not isinstance(plain, bool)
            ):
                value = int(plain)
            else:
                raise ValidationError("", expected, _describe(value))
        if not low <= value <= high:
            raise ValidationError("", expected, f"{value} is out of range [{low}, {high}]")
        return int(value)

    return conv


def _float_conv(idl: str, wire: bool) -> _Conv:
    expected = _MSG_NAMES[idl]
    single = idl == "float"

    def conv(value: Any) -> float:
        if type(value) is float and not single:
            return value
        if value is None and wire:
            return math.nan
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            plain = _scalar(value)  # numpy's: its Python value
            if isinstance(plain, bool) or not isinstance(plain, (int, float)):
                raise ValidationError("", expected, _describe(value))
            value = plain
        try:
            result = float(value)
        except OverflowError:
            raise ValidationError("", expected, f"{value} is out of range") from None
        if single and math.isfinite(result) and abs(result) > FLOAT32_MAX:
            raise ValidationError("", expected, f"{value} is out of the float32 range")
        return result

    return conv


def _string_conv(base: str, bound: int | None) -> _Conv:
    expected = base if bound is None else f"{base}<={bound}"

    def conv(value: Any) -> str:
        if not isinstance(value, str):
            raise ValidationError("", expected, _describe(value))
        if bound is not None and len(value) > bound:
            raise ValidationError("", expected, f"got a string of length {len(value)}")
        return value

    return conv


def _nested_conv(type_name: str, wire: bool, deep: bool, find: _Find) -> _Conv:
    cls_box: list[type[Message]] = []

    def conv(value: Any) -> Message:
        if not cls_box:
            cls_box.append(find(type_name))
        cls = cls_box[0]
        if isinstance(value, cls):
            if not wire and deep:
                value.validate()
            return value
        if wire and isinstance(value, Mapping):
            return cls.from_json(value)
        expected = f"{type_name} object" if wire else f"{type_name} instance"
        raise ValidationError("", expected, _describe(value))

    return conv


def _bytes_conv(expected: str, fixed: int | None, bound: int | None, wire: bool) -> _Conv:
    def conv(value: Any) -> bytes:
        if isinstance(value, bytes):
            result = value
        elif isinstance(value, bytearray) or (
            isinstance(value, memoryview) and value.format in ("B", "c")
        ):
            result = bytes(value)
        elif wire and isinstance(value, str):
            try:
                result = base64.b64decode(value, validate=True)
            except (binascii.Error, ValueError):
                raise ValidationError("", expected, "got a string that is not base64") from None
        elif wire and isinstance(value, (list, tuple, array.array, memoryview)):
            if isinstance(value, (array.array, memoryview)):
                value = value.tolist()
            try:
                if not all(type(x) is int for x in value):
                    raise ValueError
                result = bytes(value)
            except ValueError:
                for i, item in enumerate(value):
                    if type(item) is not int or not 0 <= item <= 255:
                        raise ValidationError(f"[{i}]", "uint8", _describe(item)) from None
                raise
        else:
            raise ValidationError("", expected, _describe(value))
        _check_length(len(result), fixed, bound, expected)
        return result

    return conv


def _check_length(length: int, fixed: int | None, bound: int | None, expected: str) -> None:
    if fixed is not None and length != fixed:
        raise ValidationError("", expected, f"got {length} elements")
    if bound is not None and length > bound:
        raise ValidationError("", expected, f"got {length} elements")


def _fast_float(values: list[Any] | tuple[Any, ...], single: bool) -> bool:
    """True if every item is a float (no NaN stand-ins, in range for float32)."""
    if not all(type(x) is float for x in values):
        return False
    if single and values:
        top = max(map(abs, values))
        return not (math.isfinite(top) and top > FLOAT32_MAX)
    return True


def _list_conv(
    element: _Conv,
    elem_idl: str,
    expected: str,
    fixed: int | None,
    bound: int | None,
    wire: bool,
) -> _Conv:
    """A list converter with a fast path for homogeneous primitive lists."""
    octets = elem_idl == "octet"
    int_range = _INT_RANGES.get(elem_idl)
    is_float = elem_idl in ("float", "double")
    single = elem_idl == "float"
    plain_string = elem_idl in ("string", "wstring")

    def conv(value: Any) -> list[Any]:
        if type(value) is not list:
            if not wire:
                raise ValidationError("", f"{expected} (a list)", _describe(value))
            if octets and isinstance(value, (str, bytes, bytearray)):
                value = list(_bytes_conv(expected, fixed, bound, wire)(value))
            elif isinstance(value, (memoryview, array.array)):
                value = value.tolist()
            elif not isinstance(value, tuple):
                raise ValidationError("", expected, _describe(value))
        _check_length(len(value), fixed, bound, expected)
        if int_range is not None:
            low, high = int_range
            if all(type(x) is int for x in value) and (
                not value or (low <= min(value) and max(value) <= high)
            ):
                return list(value)
        elif (is_float and _fast_float(value, single)) or (
            plain_string and all(type(x) is str for x in value)
        ):
            return list(value)
        out: list[Any] = []
        append = out.append
        for i, item in enumerate(value):
            try:
                append(element(item))
            except ValidationError as exc:
                raise exc._under(f"[{i}]") from None
        return out

    return conv


_SEQUENCE_RE = re.compile(r"^sequence<(?P<elem>.+?)(?:, (?P<bound>\d+))?>$")
_FIXED_RE = re.compile(r"^(?P<elem>.+)\[(?P<size>\d+)\]$")
_STRING_RE = re.compile(r"^(?P<base>w?string)(?:<(?P<bound>\d+)>)?$")


def _scalar_conv(idl: str, wire: bool, deep: bool, find: _Find) -> _Conv:
    if idl == "boolean":
        return _bool_conv
    if idl in _INT_RANGES:
        return _int_conv(idl)
    if idl in ("float", "double"):
        return _float_conv(idl, wire)
    match = _STRING_RE.match(idl)
    if match is not None:
        bound = match["bound"]
        return _string_conv(match["base"], int(bound) if bound else None)
    if "/" in idl:
        return _nested_conv(idl, wire, deep, find)
    raise ValueError(f"unsupported field type {idl!r}")


def _expected_name(idl: str) -> str:
    """The .msg spelling of an rclpy type string, for error messages."""
    match = _SEQUENCE_RE.match(idl)
    if match is not None:
        elem = _expected_name(match["elem"])
        return f"{elem}[<={match['bound']}]" if match["bound"] else f"{elem}[]"
    match = _FIXED_RE.match(idl)
    if match is not None:
        return f"{_expected_name(match['elem'])}[{match['size']}]"
    match = _STRING_RE.match(idl)
    if match is not None and match["bound"]:
        return f"{match['base']}<={match['bound']}"
    return _MSG_NAMES.get(idl, idl)


def _field_conv(idl: str, wire: bool, find: _Find, deep: bool = True) -> _Conv:
    """The converter (``wire``: from the wire form) or checker of a field; ``deep=False``
    takes a nested message instance as it is (checked when it was built); ``find`` gives
    the class of a nested message type (the field's class's ``_lookup``)."""
    fixed: int | None = None
    bound: int | None = None
    elem: str | None = None
    match = _SEQUENCE_RE.match(idl)
    if match is not None:
        elem = match["elem"]
        bound = int(match["bound"]) if match["bound"] else None
    else:
        match = _FIXED_RE.match(idl)
        if match is not None:
            elem = match["elem"]
            fixed = int(match["size"])
    if elem is None:
        return _scalar_conv(idl, wire, deep, find)
    expected = _expected_name(idl)
    if elem == "uint8":
        return _bytes_conv(expected, fixed, bound, wire)
    return _list_conv(_scalar_conv(elem, wire, deep, find), elem, expected, fixed, bound, wire)


def _float_enc(value: Any) -> Any:
    return value if math.isfinite(value) else None


def _floats_enc(value: Any) -> Any:
    isfinite = math.isfinite
    if all(map(isfinite, value)):
        return list(value)
    return [x if isfinite(x) else None for x in value]


def _message_enc(value: Any) -> Any:
    return value.to_json()


def _messages_enc(value: Any) -> Any:
    return [x.to_json() for x in value]


def _bytes_enc(value: Any) -> Any:
    return base64.b64encode(value).decode("ascii")


def _field_enc(idl: str) -> _Enc | None:
    """The JSON encoder of a field, or None when the value is its own JSON form."""
    elem = idl
    is_array = False
    match = _SEQUENCE_RE.match(idl) or _FIXED_RE.match(idl)
    if match is not None:
        elem = match["elem"]
        is_array = True
    if is_array:
        if elem == "uint8":
            return _bytes_enc
        if elem in ("float", "double"):
            return _floats_enc
        if "/" in elem:
            return _messages_enc
        return list
    if elem in ("float", "double"):
        return _float_enc
    if "/" in elem:
        return _message_enc
    return None


class _Codec:
    """The converters of one message class, built once from ``_fields_and_types``."""

    __slots__ = ("build", "check", "cls", "decode", "encode", "fields", "on_build")

    def __init__(self, cls: type[Message]) -> None:
        self.cls = cls
        fields_and_types = cls._fields_and_types
        find = cls._lookup
        self.decode: dict[str, _Conv] = {
            name: _field_conv(idl, True, find) for name, idl in fields_and_types.items()
        }
        self.check: tuple[tuple[str, _Conv], ...] = tuple(
            (name, _field_conv(idl, False, find)) for name, idl in fields_and_types.items()
        )
        self.encode: tuple[tuple[str, _Enc | None], ...] = tuple(
            (name, _field_enc(idl)) for name, idl in fields_and_types.items()
        )
        # at construction: nested instances were checked when they were built
        self.build: tuple[tuple[str, _Conv], ...] = tuple(
            (name, _field_conv(idl, False, find, deep=False))
            for name, idl in fields_and_types.items()
        )
        self.on_build = _build_check(cls, dict(self.build))
        # from_json's way to an instance without checking twice: (name, default, factory)
        self.fields: tuple[tuple[str, Any, Callable[[], Any] | None], ...] = tuple(
            (f.name, f.default, None if f.default_factory is _dc.MISSING else f.default_factory)
            for f in _dc.fields(cls)
        ) if _dc.is_dataclass(cls) else ()


def _fast_test(idl: str, var: str) -> str | None:
    """A Python expression true when ``var`` surely fits a scalar field of type ``idl``
    (None: no fast test; the field's checker decides). What it does not pass goes to the
    checker, which accepts it or raises."""
    if idl == "boolean":
        return f"({var} is True or {var} is False)"
    if idl in _INT_RANGES:
        low, high = _INT_RANGES[idl]
        return f"(type({var}) is int and {low} <= {var} <= {high})"
    if idl == "double":
        return f"type({var}) is float"
    if idl == "float":
        return f"(type({var}) is float and -{FLOAT32_MAX!r} <= {var} <= {FLOAT32_MAX!r})"
    if idl in ("string", "wstring"):
        return f"type({var}) is str"
    if idl in ("sequence<uint8>", "sequence<octet>"):
        return f"type({var}) is bytes"
    return None


_ELEMENT_TYPES = {"boolean": bool, "double": float, "string": str, "wstring": str,
                  **{idl: int for idl in _INT_RANGES}}


def _fast_list_test(idl: str, key: str, types: dict[str, Any], find: _Find) -> str | None:
    """The fast test of a nested message or a list field (see _fast_test); the classes
    (``find`` gives them) and element types it names are put in ``types`` under ``key``."""
    match = _SEQUENCE_RE.match(idl) or _FIXED_RE.match(idl)
    if match is None:
        if "/" not in idl:
            return None
        types[key] = find(idl)  # a nested message: its own class
        return f"type(v) is {key}"
    elem = match["elem"]
    size = match.groupdict().get("size")
    bound = match.groupdict().get("bound")
    kind = find(elem) if "/" in elem else _ELEMENT_TYPES.get(elem)
    if kind is None:
        return None
    types[key] = frozenset({kind})
    test = f"type(v) is list and {{*map(type, v)}} <= {key}"
    if size is not None:
        test += f" and len(v) == {size}"
    elif bound is not None:
        test += f" and len(v) <= {bound}"
    if elem in _INT_RANGES:
        low, high = _INT_RANGES[elem]
        test += f" and (not v or ({low} <= min(v) and max(v) <= {high}))"
    return f"({test})"


def _build_check(cls: type[Message], convs: dict[str, _Conv]) -> Callable[[Message], None]:
    """``cls``'s construction check, written out once as one function: a fast test per
    scalar field inline, the field's checker for the rest and for what the test lets by."""
    lines = ["def check(self):"]
    nested: dict[str, type[Message]] = {}
    for name, idl in cls._fields_and_types.items():
        if not name.isidentifier() or keyword.iskeyword(name):
            raise ValueError(f"{cls._type}: field name {name!r} is not a Python name")
        lines.append(f"    v = self.{name}")
        test = _fast_test(idl, "v")
        if test is None:
            test = _fast_list_test(idl, f"T_{name}", nested, cls._lookup)
        if test is None:
            lines.append(f"    slow(self, {name!r}, v)")
        else:
            lines.append(f"    if not {test}: slow(self, {name!r}, v)")
    if len(lines) == 1:
        lines.append("    pass")

    def slow(msg: Message, name: str, value: Any) -> None:
        try:
            convs[name](value)
        except ValidationError as exc:
            err = exc._under(name)
            raise ValidationError(err.path, err.expected,
                                  f"{err.problem} (building {msg._type})") from None

    namespace: dict[str, Any] = {"slow": slow, **nested}
    exec("\n".join(lines), namespace)  # our own text, written from the field table
    check: Callable[[Message], None] = namespace["check"]
    return check


def _codec(cls: type[Message]) -> _Codec:
    """``cls``'s converters, built on first use and kept on the class itself (so they go
    with it: a robot's types that a relay releases take their converters along)."""
    codec: _Codec | None = getattr(cls, "_codec_", None)
    if codec is None or codec.cls is not cls:  # (a subclass finds its base's)
        codec = _Codec(cls)
        type.__setattr__(cls, "_codec_", codec)
    return codec


class Message:
    """Base of every generated message class (see the module docstring for the contract).

    ``repr()`` stays short for large fields: long byte strings, lists and texts are
    summarised (``data=<921600 bytes>``), so logging or printing an image is safe.
    """

    __slots__ = ()

    _type: ClassVar[str]
    _definition: ClassVar[str]
    _fields_and_types: ClassVar[dict[str, str]]
    _lookup: ClassVar[_Find]
    """How the class finds the message types its fields name: :func:`lookup_message` (set
    below); a :class:`msgs.dynamic.TypeStore`'s own lookup for the classes it built."""

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if "__repr__" not in cls.__dict__:  # set before @dataclass, which then keeps it
            cls.__repr__ = _message_repr  # type: ignore[method-assign, assignment]

    @classmethod
    def get_fields_and_field_types(cls) -> dict[str, str]:
        """Field name -> type string, as rclpy spells it (a copy)."""
        return dict(cls._fields_and_types)

    def to_json(self) -> dict[str, Any]:
        """The rosbridge JSON form of this message (a new dict, safe to mutate)."""
        out: dict[str, Any] = {}
        for name, enc in _codec(type(self)).encode:
            value = getattr(self, name)
            out[name] = value if enc is None else enc(value)
        return out

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Self:
        """Build a message from its wire form (JSON or CBOR decoded); see the module doc.

        Raises :class:`ValidationError` naming the field path and the expected type.
        """
        if not isinstance(data, Mapping):
            raise ValidationError("", f"{cls._type} object", _describe(data))
        codec = _codec(cls)
        decode = codec.decode
        kwargs: dict[str, Any] = {}
        for key, value in data.items():
            conv = decode.get(key)
            if conv is None:
                fields = ", ".join(cls._fields_and_types) or "none"
                raise ValidationError(
                    str(key), f"a field of {cls._type} ({fields})", "got an unknown field"
                )
            try:
                kwargs[key] = conv(value)
            except ValidationError as exc:
                raise exc._under(key) from None
        # converted, hence checked: built as __init__ would, without __post_init__'s check
        msg = object.__new__(cls)
        for name, default, factory in codec.fields:
            value = kwargs.get(name, _MISSING)
            if value is _MISSING:
                value = default if factory is None else factory()
            object.__setattr__(msg, name, value)
        return msg

    def __post_init__(self) -> None:
        """Check each field's kind, range and length when the message is built (a nested
        message was checked when it was built); see :meth:`validate`.

        Raises :class:`ValidationError` naming the field, the expected type and the type.
        """
        cls = type(self)
        check = _codec(cls).on_build
        if "__post_init__" not in cls.__dict__:
            cls.__post_init__ = check  # type: ignore[method-assign, assignment]  # directly now
        check(self)

    def _repr_html_(self) -> str:
        """The message as an HTML table for Jupyter: a row per field, nested messages as
        nested tables, large fields summarised as ``repr()`` does."""
        return _message_html(self)

    def validate(self) -> None:
        """Check every field's Python-side value (kind, range, length, nesting).

        Raises :class:`ValidationError` naming the field path and the expected type.
        """
        for name, conv in _codec(type(self)).check:
            try:
                conv(getattr(self, name))
            except ValidationError as exc:
                raise exc._under(name) from None


_SHORT_ITEMS = 16
_SHORT_BYTES = 32
_SHORT_TEXT = 200


def _short_repr(value: Any) -> str:
    """``repr(value)``, summarised when it is a long byte string, list or text."""
    if isinstance(value, bytes | bytearray | memoryview) and len(value) > _SHORT_BYTES:
        return f"<{len(value)} bytes>"
    if isinstance(value, list | tuple | array.array) and len(value) > _SHORT_ITEMS:
        head = ", ".join(_short_repr(v) for v in value[:3])
        return f"[{head}, ... <{len(value)} items>]"
    if isinstance(value, list):
        return "[" + ", ".join(_short_repr(v) for v in value) + "]"
    if isinstance(value, str) and len(value) > _SHORT_TEXT:
        return f"{value[:40]!r}... <{len(value)} chars>"
    return repr(value)


def _message_repr(self: Message) -> str:
    fields = ", ".join(f"{name}={_short_repr(getattr(self, name))}"
                       for name in self._fields_and_types)
    return f"{type(self).__name__}({fields})"


def _message_html(msg: Message) -> str:
    rows = []
    for name in msg._fields_and_types:
        value = getattr(msg, name)
        shown = (_message_html(value) if isinstance(value, Message)
                 else f"<code>{html.escape(_short_repr(value))}</code>")
        rows.append(f"<tr><th style='text-align:left'>{html.escape(name)}</th>"
                    f"<td style='text-align:left'>{shown}</td></tr>")
    return (f"<table><caption style='text-align:left'>{html.escape(msg._type)}</caption>"
            + "".join(rows) + "</table>")


class Service:
    """Base of the generated service types: a namespace holding ``Request`` and ``Response``."""

    _type: ClassVar[str]
    _definition: ClassVar[str]
    Request: ClassVar[type[Message]]
    Response: ClassVar[type[Message]]

    def __init__(self) -> None:
        """Services are not messages: build ``Request``/``Response`` instead."""
        raise TypeError(
            f"{type(self).__name__} is a service type; instantiate .Request or .Response"
        )


class Action:
    """Base of the generated action types: a namespace of ``Goal``, ``Result``, ``Feedback``."""

    _type: ClassVar[str]
    _definition: ClassVar[str]
    Goal: ClassVar[type[Message]]
    Result: ClassVar[type[Message]]
    Feedback: ClassVar[type[Message]]

    def __init__(self) -> None:
        """Actions are not messages: build ``Goal``/``Result``/``Feedback`` instead."""
        raise TypeError(
            f"{type(self).__name__} is an action type; instantiate .Goal, .Result or .Feedback"
        )


_KINDS = ("msg", "srv", "action")
_NAME_RE = re.compile(
    r"^(?P<pkg>[a-z][a-z0-9_]*)/(?:(?P<kind>msg|srv|action)/)?(?P<name>[A-Z][A-Za-z0-9_]*)$"
)
_RESERVED = frozenset({"runtime", "parser", "generator", "interfaces"})
_CACHE: dict[str, type[Message] | type[Service] | type[Action]] = {}


def _find(
    package: str, kind: str, name: str
) -> type[Message] | type[Service] | type[Action] | None:
    module_name = f"msgs.{package}.{kind}"
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name is not None and module_name.startswith(exc.name):
            return None
        raise
    if name not in getattr(module, "__all__", ()):
        return None
    found: type[Message] | type[Service] | type[Action] = getattr(module, name)
    return found


def _case_fixed(type_name: str) -> str | None:
    """The generated type whose name differs from ``type_name`` only in case, if any."""
    package, _, rest = type_name.lower().partition("/")
    kind, _, name = rest.rpartition("/")
    if not package or not name or kind not in ("", *_KINDS) or package not in available_packages():
        return None
    for full in available_types(package):
        pkg_kind, _, found = full.rpartition("/")
        if found.lower() == name and (not kind or pkg_kind.endswith("/" + kind)):
            return full
    return None


def lookup(type_name: str) -> type[Message] | type[Service] | type[Action]:
    """The generated class for ``pkg/Name`` or ``pkg/{msg,srv,action}/Name`` (or the class
    :func:`register` made findable under that name).

    ``pkg/Name`` is searched as a message, then a service, then an action. Service and
    action parts are found too (``pkg/srv/Name_Request``, ``pkg/action/Name_Goal``).
    Raises :class:`UnknownTypeError` (a LookupError) for unknown or malformed names.
    """
    cached = _CACHE.get(type_name)
    if cached is not None:
        return cached
    found = lookup_generated(type_name)
    _CACHE[type_name] = found
    return found


_GENERATED: dict[str, type[Message] | type[Service] | type[Action]] = {}


def lookup_generated(type_name: str) -> type[Message] | type[Service] | type[Action]:
    """Like :func:`lookup`, among the types ``msgs`` generates only (not the classes
    :func:`register` made findable): what every robot's types share on a relay."""
    cached = _GENERATED.get(type_name)
    if cached is not None:
        return cached
    match = _NAME_RE.match(type_name) if isinstance(type_name, str) else None
    if match is None:
        fixed = _case_fixed(type_name) if isinstance(type_name, str) else None
        if fixed is not None:  # the right name in the wrong case: say so, not "format"
            raise UnknownTypeError(type_name, f"did you mean {fixed!r}? (type names are "
                                   "CamelCase, packages lower case)")
        raise UnknownTypeError(
            str(type_name), "expected 'package/Name' or 'package/msg|srv|action/Name'"
        )
    package, kind, name = match["pkg"], match["kind"], match["name"]
    if package in _RESERVED:
        raise UnknownTypeError(type_name, f"no generated package {package!r}")
    for candidate in (kind,) if kind else _KINDS:
        found = _find(package, candidate, name)
        if found is not None:
            _GENERATED[type_name] = found
            return found
    where = f"{package}/{kind}" if kind else package
    raise UnknownTypeError(type_name, f"no type {name!r} in {where} among the generated types")


def register(*classes: type[Message] | type[Service] | type[Action]) -> None:
    """Make classes that live outside ``msgs/`` findable by :func:`lookup`.

    Modules written by ``roslibpy-lite interface gen`` and types built at runtime by
    :mod:`msgs.dynamic` call this; the full name and the short ``pkg/Name`` are both
    registered (a message wins the short name over a service or action, as in lookup).
    """
    for cls in classes:
        full: str = cls._type
        _CACHE[full] = cls
        package, kind, name = full.split("/")
        if kind == "msg":
            _CACHE[f"{package}/{name}"] = cls
        else:
            _CACHE.setdefault(f"{package}/{name}", cls)


Find = Callable[[str], "type[Message] | type[Service] | type[Action]"]
"""A lookup by type name: :func:`lookup`, or a :class:`msgs.dynamic.TypeStore`'s."""


def lookup_message(type_name: str, among: Find | None = None) -> type[Message]:
    """Like :func:`lookup` (``among``: another lookup), for message types (including
    service and action parts)."""
    found = (among or lookup)(type_name)
    if not (isinstance(found, type) and issubclass(found, Message)):
        raise UnknownTypeError(type_name, f"{found._type} is not a message type")
    return found


Message._lookup = staticmethod(lookup_message)


def lookup_service(type_name: str, among: Find | None = None) -> type[Service]:
    """Like :func:`lookup` (``among``: another lookup), for service types."""
    if _NAME_RE.match(type_name) and type_name.count("/") == 1:
        type_name = type_name.replace("/", "/srv/")
    found = (among or lookup)(type_name)
    if not (isinstance(found, type) and issubclass(found, Service)):
        raise UnknownTypeError(type_name, f"{found._type} is not a service type")
    return found


def lookup_action(type_name: str, among: Find | None = None) -> type[Action]:
    """Like :func:`lookup` (``among``: another lookup), for action types."""
    if _NAME_RE.match(type_name) and type_name.count("/") == 1:
        type_name = type_name.replace("/", "/action/")
    found = (among or lookup)(type_name)
    if not (isinstance(found, type) and issubclass(found, Action)):
        raise UnknownTypeError(type_name, f"{found._type} is not an action type")
    return found


_MSGS_DIR = Path(__file__).resolve().parent


def available_packages() -> list[str]:
    """The packages with generated types, sorted (no module is imported)."""
    return sorted(
        d.name
        for d in _MSGS_DIR.iterdir()
        if d.name not in _RESERVED
        and _NAME_RE.match(f"{d.name}/X")
        and any((d / f"{kind}.py").is_file() for kind in _KINDS)
    )


def available_types(package: str | None = None) -> list[str]:
    """Every generated type as ``pkg/kind/Name``, sorted; imports the modules it lists.

    Messages, services and actions are listed; the parts of services and actions
    (``Name_Request``, ``Name_Goal``, ...) are reached through their namespace.
    """
    packages = available_packages() if package is None else [package]
    names: list[str] = []
    for pkg in packages:
        for kind in _KINDS:
            if not (_MSGS_DIR / pkg / f"{kind}.py").is_file():
                continue
            module = importlib.import_module(f"msgs.{pkg}.{kind}")
            for name in module.__all__:
                cls = getattr(module, name)
                if kind == "msg" or issubclass(cls, (Service, Action)):
                    names.append(cls._type)
    return sorted(names)
