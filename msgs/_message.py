"""The base classes of the generated types: :class:`Message` (its checks and JSON form, through
a codec built once per class from :mod:`msgs._fields`; a short ``repr()`` and an HTML table),
and the namespaces :class:`Service` and :class:`Action`. Exported by :mod:`msgs.runtime`."""

from __future__ import annotations

import array
import dataclasses as _dc
import html
import keyword
from collections.abc import Callable, Mapping
from typing import Any, ClassVar, Self

from ._errors import ValidationError, _describe
from ._fields import _FIXED_RE, _INT_RANGES, _SEQUENCE_RE, _Conv, _Enc, _field_conv, _field_enc
from ._primitives import FLOAT32_MAX

_MISSING = object()
_Find = Callable[[str], "type[Message]"]


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
