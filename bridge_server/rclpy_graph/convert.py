"""ROS message <-> rosbridge JSON / CBOR conversion, compiled once per message type.

``converter_for(cls)`` walks a message class's ``SLOT_TYPES`` a single time
and generates specialised Python functions (with ``exec``) for the three hot
paths. The result is cached per class, so every later call is one dict lookup.

API
---
``converter_for(msg_cls) -> Converter``  (cached, thread safe)

``Converter``
    ``type_name``      canonical ``pkg/msg/Type``
    ``fields``         field names in declaration order (zip a list of service
                       ``args`` onto these)
    ``msg_cls``        the rclpy class
    ``to_obj(msg)``    JSON-ready plain dict (see rules below)
    ``to_json(msg)``   compact JSON text of the message object only
    ``to_cbor_obj(msg)`` dict with ``bytes`` and ``cbor2.CBORTag`` typed arrays,
                       to embed in ``{"op": "publish", ...}`` before ``cbor2.dumps``
    ``from_obj(obj, path="")`` build a new message from a decoded JSON object;
                       raises :class:`ConversionError`. ``path`` prefixes the
                       field paths in error messages (e.g. ``"msg"``).

``encode_publish_json(topic, msg_json) -> str``
    ``{"op":"publish","topic":...,"msg":<msg_json>}`` by string concatenation,
    so one ``to_json`` result is shared by every subscriber.
``encode_publish_cbor(topic, ros_msg, conv) -> bytes``
    The whole publish op CBOR-encoded (compression ``"cbor"``).
``encode_publish_cbor_raw(topic, serialized, stamp_ns) -> bytes``
    compression ``"cbor-raw"``: msg is ``{"secs", "nsecs", "bytes"}``.
``serialize(ros_msg) -> bytes`` / ``deserialize(data, msg_cls)``
    CDR via ``rclpy.serialization`` (for cbor-raw and tests).
``tune_allocator() -> bool``
    :func:`bridge_server.allocator.tune_allocator`, which the bridge and the relay
    call at start-up (glibc's mmap threshold fixed: buffers up to 8 MiB reused from
    the heap, larger ones given back when freed).
``now_ns``
    Module attribute, a zero-argument callable giving the time used for
    ``builtin_interfaces/Time`` fields given as the string ``"now"``
    (default ``time.time_ns``; the bridge may replace it with its node clock).

Conversion rules, ROS -> JSON (``to_obj``/``to_json``)
    * ``uint8``/``char`` arrays of any kind (fixed, bounded, unbounded) become
      a base64 string. ``byte`` (IDL ``octet``) values become ints and
      ``byte`` arrays lists of ints, as in the reference bridge.
    * Float NaN, +Inf and -Inf become ``null`` (scalars and array items).
    * Numeric arrays become lists; ``float32`` items are the exact double value
      of the float32 (as ``array.tolist()`` gives).
    * ``builtin_interfaces/Time`` and ``Duration`` are ordinary messages:
      ``{"sec": int, "nanosec": int}``.

Conversion rules, ROS -> CBOR (``to_cbor_obj``)
    * ``uint8``/``char`` and ``byte`` arrays become CBOR byte strings.
    * Other numeric arrays (fixed, bounded, unbounded) become RFC 8746
      little-endian typed arrays: uint16 69, uint32 70, uint64 71, int8 72,
      int16 77, int32 78, int64 79, float32 85, float64 86.
    * Bool and string arrays stay plain arrays; floats stay floats (CBOR can
      carry NaN and infinities, so no ``null`` there).

Conversion rules, JSON -> ROS (``from_obj``)
    * A message is a JSON object (any ``Mapping``). Missing fields keep their
      defaults; a key the type lacks is an error naming it.
    * ``bool`` fields take only ``true``/``false``; ``byte`` fields ints 0..255.
    * Integer fields take JSON integers in the type's range (``bool`` is
      rejected). A float with an integral value (``3.0``, ``1e3``) is accepted
      and converted; any other float is rejected.
    * Float fields take numbers, ints included; ``null`` means NaN. ``float32``
      values beyond the float32 range (other than infinities) are rejected.
    * String fields take strings; ``string<=N`` bounds count UTF-8 bytes
      (``wstring<=N`` bounds count characters).
    * ``uint8``/``char`` arrays take a base64 string, a list of ints 0..255,
      or ``bytes``/``bytearray``. ``byte`` arrays take the same.
    * Arrays take lists (or tuples). Fixed arrays need exactly N items,
      bounded ones at most N.
    * ``builtin_interfaces/Time`` and ``Duration`` also accept the ROS 1 keys
      ``secs``/``nsecs``; a ``Time`` may be the string ``"now"``.
    * The returned message never shares mutable values with ``obj``.

Every error is a :class:`ConversionError` with ``path`` (``pose.position.x``,
``points[3].x``), ``expected`` (``float64``, ``array of 3 float64``, ...) and
a message naming both and a short description of what was received (never
the whole payload).
"""

from __future__ import annotations

import array
import binascii
import importlib
import json
import sys
import threading
import time
from collections.abc import Callable, Mapping
from typing import Any, Final, Protocol

import cbor2
import numpy
from rosidl_parser import definition as idl

from bridge_server.allocator import tune_allocator
from bridge_server.rclpy_graph.types import type_name_of
from msgs._primitives import FLOAT32_MAX, SIZED_INTEGER_RANGES
from rosbridge_core.codec import cdr_json
from rosbridge_core.codec.publish import (
    encode_publish_cbor,
    encode_publish_cbor_raw,
    encode_publish_json,
)
from rosbridge_core.interfaces import MISSING as _MISSING
from rosbridge_core.interfaces import ConversionError, args_mapping
from rosbridge_core.interfaces import describe as _describe

__all__ = [
    "ConversionError",
    "Converter",
    "FromObj",
    "args_mapping",
    "converter_for",
    "deserialize",
    "encode_publish_cbor",
    "encode_publish_cbor_raw",
    "encode_publish_json",
    "now_ns",
    "serialize",
    "tune_allocator",
]

now_ns: Callable[[], int] = time.time_ns

_LITTLE: Final = sys.byteorder == "little"

_INT_RANGES: Final = SIZED_INTEGER_RANGES
# IDL names of the non-explicit integer types map onto explicit ones.
_INT_ALIASES: Final = {
    "short": "int16",
    "unsigned short": "uint16",
    "long": "int32",
    "unsigned long": "uint32",
    "long long": "int64",
    "unsigned long long": "uint64",
}
_FLOAT_NAMES: Final = {"float": "float32", "double": "float64", "long double": "float64"}
_TYPECODES: Final = {
    "int8": "b",
    "uint8": "B",
    "int16": "h",
    "uint16": "H",
    "int32": "i",
    "uint32": "I",
    "int64": "q",
    "uint64": "Q",
    "float32": "f",
    "float64": "d",
}
_CBOR_TAGS: Final = {
    "uint16": 69,
    "uint32": 70,
    "uint64": 71,
    "int8": 72,
    "int16": 77,
    "int32": 78,
    "int64": 79,
    "float32": 85,
    "float64": 86,
}

_json_encode: Callable[[Any], str] = json.JSONEncoder(
    separators=(",", ":"), allow_nan=False, check_circular=False, ensure_ascii=False
).encode
_encode_str: Callable[[str], str] = json.encoder.encode_basestring
_a2b = binascii.a2b_base64
_Tag = cbor2.CBORTag
_cbor_dumps: Callable[[Any], bytes] = cbor2.dumps


# --------------------------------------------------------------------------------------------
# Field model


class _Field:
    """One message field, classified once from its rosidl slot type."""

    __slots__ = (
        "bound",
        "container",
        "elem",
        "elem_name",
        "name",
        "size",
        "sub",
        "subclass",
        "wide",
    )

    def __init__(self, name: str, slot_type: Any, owner: type[Any]) -> None:
        self.name = name
        self.container: str | None = None  # None, "array", "bseq", "useq"
        self.size = 0  # fixed size or maximum size
        t = slot_type
        if isinstance(t, idl.Array):
            self.container, self.size, t = "array", t.size, t.value_type
        elif isinstance(t, idl.BoundedSequence):
            self.container, self.size, t = "bseq", t.maximum_size, t.value_type
        elif isinstance(t, idl.UnboundedSequence):
            self.container, t = "useq", t.value_type
        self.bound: int | None = None
        self.wide = False
        self.subclass: type[Any] | None = None
        self.sub: Converter | None = None
        if isinstance(t, idl.BasicType):
            tn = t.typename
            if tn == "boolean":
                self.elem, self.elem_name = "bool", "bool"
            elif tn == "octet":
                self.elem, self.elem_name = "octet", "byte"
            elif tn in ("char", "wchar"):
                self.elem, self.elem_name = "char", tn
            elif tn in _FLOAT_NAMES:
                self.elem = self.elem_name = _FLOAT_NAMES[tn]
            else:
                self.elem = self.elem_name = _INT_ALIASES.get(tn, tn)
                if self.elem not in _INT_RANGES:
                    raise TypeError(f"unsupported basic type {tn!r} for field {name!r}")
        elif isinstance(t, idl.AbstractString | idl.AbstractWString):
            self.elem = "string"
            self.wide = isinstance(t, idl.AbstractWString)
            self.bound = getattr(t, "maximum_size", None)
            self.elem_name = f"string<={self.bound}" if self.bound is not None else "string"
            if isinstance(t, idl.AbstractWString):
                self.elem_name = "w" + self.elem_name
        elif isinstance(t, idl.NamespacedType):
            self.subclass = _nested_class(t, owner)
            self.elem = "msg"
            self.elem_name = "/".join([*t.namespaces, t.name])
        else:
            raise TypeError(f"unsupported slot type {t!r} for field {name!r}")

    def expected(self) -> str:
        """Human name of the expected JSON value."""
        if self.container is None:
            return self.elem_name if self.elem != "msg" else f"object of type {self.elem_name}"
        item = self.elem_name if self.elem != "msg" else f"{self.elem_name} objects"
        if self.elem == "uint8":
            item = "uint8 (base64 string or array of ints)"
        elif self.elem == "octet":
            item = "byte (base64 string or array of ints)"
        if self.container == "array":
            return f"array of {self.size} {item}"
        if self.container == "bseq":
            return f"array of at most {self.size} {item}"
        return f"array of {item}"


def _nested_class(t: Any, owner: type[Any]) -> type[Any]:
    """The rclpy class of a nested field type.

    Action parts such as ``Fibonacci_Goal`` are not attributes of the
    ``pkg.action`` package, only of the private module that also defines the
    owning class, so look there second.
    """
    module = importlib.import_module(".".join(t.namespaces))
    found = getattr(module, t.name, None)
    if found is None:
        found = getattr(sys.modules[owner.__module__], t.name, None)
    if not isinstance(found, type):
        raise TypeError(f"cannot find the class of nested type {'/'.join([*t.namespaces, t.name])}")
    return found


# --------------------------------------------------------------------------------------------
# Inbound scalar validators: (value, path) -> stored value, or raise ConversionError


def _int_checker(name: str) -> Callable[[Any, str], int]:
    lo, hi = _INT_RANGES[name]

    def check(v: Any, path: str) -> int:
        t = type(v)
        if t is int or (isinstance(v, int) and t is not bool):
            if lo <= v <= hi:
                return int(v)
            raise ConversionError(path, name, v, f"value {v} out of range for {name} [{lo}, {hi}]")
        if t is float and v.is_integer():
            iv = int(v)
            if lo <= iv <= hi:
                return iv
            raise ConversionError(
                path, name, v, f"value {v!r} out of range for {name} [{lo}, {hi}]"
            )
        raise ConversionError(path, name, v)

    return check


def _float_checker(name: str) -> Callable[[Any, str], float]:
    f32 = name == "float32"

    def check(v: Any, path: str) -> float:
        t = type(v)
        f: float
        if t is float:
            f = v
        elif v is None:
            return float("nan")
        elif (t is int or isinstance(v, int | float)) and t is not bool:
            try:
                f = float(v)
            except OverflowError:
                raise ConversionError(
                    path, name, v, f"value {_describe(v)} out of range for {name}"
                ) from None
        else:
            raise ConversionError(path, name, v)
        if f32 and abs(f) > FLOAT32_MAX and f not in (float("inf"), float("-inf")):
            raise ConversionError(path, name, v, f"value {f!r} out of range for float32")
        return f

    return check


def _bool_check(v: Any, path: str) -> bool:
    if v is True or v is False:
        return v
    raise ConversionError(path, "bool", v)


def _octet_check(v: Any, path: str) -> bytes:
    if type(v) is int and 0 <= v <= 255:
        return bytes((v,))
    if isinstance(v, bytes) and len(v) == 1:
        return v
    if type(v) is float and v.is_integer() and 0 <= v <= 255:
        return bytes((int(v),))
    raise ConversionError(path, "byte (integer 0..255)", v)


def _char_check(v: Any, path: str) -> str:
    if type(v) is str and len(v) == 1:
        return v
    if type(v) is int and 0 <= v <= 255:
        return chr(v)
    raise ConversionError(path, "char (string of one character)", v)


def _string_checker(bound: int | None, expected: str, wide: bool) -> Callable[[Any, str], str]:
    """Strings; ``string<=N`` counts UTF-8 bytes, ``wstring<=N`` counts characters."""

    def check(v: Any, path: str) -> str:
        if not isinstance(v, str):
            raise ConversionError(path, expected, v)
        s = str(v)
        if bound is None or len(s) <= (bound if wide else bound // 4):
            return s
        size = len(s) if wide else len(s.encode("utf-8"))
        if size > bound:
            unit = "characters" if wide else "bytes"
            raise ConversionError(
                path, expected, v, f"string of {size} {unit} exceeds the bound {expected}"
            )
        return s

    return check


def _scalar_checker(f: _Field) -> Callable[[Any, str], Any]:
    e = f.elem
    if e == "bool":
        return _bool_check
    if e == "octet":
        return _octet_check
    if e == "char":
        return _char_check
    if e == "string":
        return _string_checker(f.bound, f.elem_name, f.wide)
    if e in ("float32", "float64"):
        return _float_checker(e)
    return _int_checker(e)


# --------------------------------------------------------------------------------------------
# Inbound array validators


def _elem_path(path: str, i: int) -> str:
    return f"{path}[{i}]"


def _check_len(f: _Field, n: int, path: str, v: object) -> None:
    """Fixed arrays need exactly ``size`` items, bounded sequences at most ``size``."""
    if (f.container == "array" and n != f.size) or (f.container == "bseq" and n > f.size):
        raise ConversionError(path, f.expected(), v, f"expected {f.expected()}, got {n} items")


def _decode_binary(f: _Field, v: Any, path: str) -> bytes:
    """uint8/byte arrays: base64 text, list of ints, or bytes -> bytes."""
    t = type(v)
    if t is str:
        try:
            data = _a2b(v, strict_mode=True)
        except (binascii.Error, ValueError):
            try:
                data = _a2b("".join(v.split()), strict_mode=True)
            except (binascii.Error, ValueError) as exc:
                raise ConversionError(
                    path, f.expected(), v, f"expected {f.expected()}, got invalid base64 ({exc})"
                ) from None
    elif t is list or t is tuple:
        try:
            data = bytes(v)
            ok = not data or set(map(type, v)) == {int}
        except (TypeError, ValueError):
            ok = False
        if not ok:
            for i, x in enumerate(v):
                if type(x) is not int or not 0 <= x <= 255:
                    raise ConversionError(
                        _elem_path(path, i), f"{f.elem_name} (integer 0..255)", x
                    )
            data = bytes(v)  # pragma: no cover - unreachable: some item was bad
    elif isinstance(v, bytes | bytearray | memoryview):
        data = bytes(v)
    else:
        raise ConversionError(path, f.expected(), v)
    _check_len(f, len(data), path, v)
    return data


def _array_checker(f: _Field) -> Callable[[Any, str], Any]:
    """Validator for an array field: (value, path_of_field) -> stored value."""
    e = f.elem
    fixed = f.container == "array"
    expected = f.expected()

    if e == "uint8":
        if fixed:

            def conv_u8_fixed(v: Any, path: str) -> Any:
                return numpy.frombuffer(_decode_binary(f, v, path), dtype=numpy.uint8).copy()

            return conv_u8_fixed

        def conv_u8(v: Any, path: str) -> Any:
            return array.array("B", _decode_binary(f, v, path))

        return conv_u8

    if e == "octet":

        def conv_octet(v: Any, path: str) -> Any:
            data = _decode_binary(f, v, path)
            return [data[i : i + 1] for i in range(len(data))]

        return conv_octet

    def as_list(v: Any, path: str) -> list[Any]:
        t = type(v)
        if t is list:
            lst: list[Any] = v
        elif t is tuple:
            lst = list(v)
        else:
            raise ConversionError(path, expected, v)
        _check_len(f, len(lst), path, v)
        return lst

    if e in _INT_RANGES:
        code = _TYPECODES[e]
        check = _int_checker(e)
        dtype = numpy.dtype(code)

        def conv_int(v: Any, path: str) -> Any:
            lst = as_list(v, path)
            arr = None
            if set(map(type, lst)) <= {int}:
                try:
                    arr = array.array(code, lst)
                except OverflowError:
                    arr = None
            if arr is None:
                arr = array.array(code, [check(x, _elem_path(path, i)) for i, x in enumerate(lst)])
            if fixed:
                return numpy.frombuffer(arr, dtype=dtype).copy()
            return arr

        return conv_int

    if e in ("float32", "float64"):
        code = _TYPECODES[e]
        fcheck = _float_checker(e)
        dtype = numpy.dtype(code)
        f32 = e == "float32"

        def conv_float(v: Any, path: str) -> Any:
            lst = as_list(v, path)
            arr = None
            if set(map(type, lst)) <= {float, int}:
                try:
                    arr = array.array(code, lst)
                except (OverflowError, TypeError):
                    arr = None
                if arr is not None and f32:
                    s = sum(arr)
                    if s - s != 0.0:  # some item is inf or nan: check the source values
                        arr = None
            if arr is None:
                arr = array.array(code, [fcheck(x, _elem_path(path, i)) for i, x in enumerate(lst)])
            if fixed:
                return numpy.frombuffer(arr, dtype=dtype).copy()
            return arr

        return conv_float

    if e == "bool":

        def conv_bool(v: Any, path: str) -> Any:
            lst = as_list(v, path)
            if set(map(type, lst)) <= {bool}:
                return lst if lst is not v else list(lst)
            for i, x in enumerate(lst):
                _bool_check(x, _elem_path(path, i))
            raise AssertionError("unreachable")  # pragma: no cover

        return conv_bool

    if e in ("string", "char"):
        scheck = _scalar_checker(f)
        simple = e == "string" and f.bound is None

        def conv_str(v: Any, path: str) -> Any:
            lst = as_list(v, path)
            if simple and set(map(type, lst)) <= {str}:
                return lst if lst is not v else list(lst)
            return [scheck(x, _elem_path(path, i)) for i, x in enumerate(lst)]

        return conv_str

    if e == "msg":

        def conv_msg(v: Any, path: str) -> Any:
            lst = as_list(v, path)
            sub = f.sub
            assert sub is not None
            fo = sub.from_obj
            return [fo(x, f"{path}[{i}]") for i, x in enumerate(lst)]

        return conv_msg

    raise TypeError(f"unsupported array element {e!r}")  # pragma: no cover


# --------------------------------------------------------------------------------------------
# Outbound helpers used by generated code


def _floats(lst: list[Any]) -> list[Any]:
    """NaN/Inf -> None in a list of floats (fast when all are finite)."""
    s = sum(lst)  # finite unless some item is NaN/Inf (or the sum overflows: then check each)
    if s - s == 0.0:
        return lst
    return [x if x - x == 0.0 else None for x in lst]


def _octets(v: Any) -> list[int]:
    return list(b"".join(v))


def _le_bytes(v: Any) -> bytes:
    """Little-endian bytes of an array.array or numpy array."""
    if isinstance(v, array.array):
        a = array.array(v.typecode, v)
        a.byteswap()
        return a.tobytes()
    return bytes(numpy.asarray(v).byteswap())



def _float_text(x: Any) -> str:
    """JSON text of a float field value that is not a finite float (slow path)."""
    if isinstance(x, float):
        return "null"  # NaN or an infinity
    if isinstance(x, int) and not isinstance(x, bool):
        return int.__repr__(x)
    raise TypeError(f"float field holds a {type(x).__name__}")


_INT8_TEXT: Final = tuple(str(b - 256 if b > 127 else b) for b in range(256))


def _int8_text(v: Any) -> str:
    """JSON text of an int8 array (array.array or numpy) via a byte -> text table."""
    return "[" + ",".join(map(_INT8_TEXT.__getitem__, bytes(v))) + "]"


def _merge_literals(parts: list[tuple[bool, str]]) -> list[str]:
    """Source fragments for ``(is_literal, text)`` pieces, adjacent literals merged."""
    out: list[tuple[bool, str]] = []
    for lit, text in parts:
        if lit and out and out[-1][0]:
            out[-1] = (True, out[-1][1] + text)
        else:
            out.append((lit, text))
    return [repr(text) if lit else text for lit, text in out]


def _mapping(o: Any, path: str, type_name: str) -> Mapping[str, Any]:
    if isinstance(o, Mapping):
        return o
    raise ConversionError(path, f"object of type {type_name}", o)


def _unknown(o: Mapping[str, Any], fields: frozenset[str], prefix: str, type_name: str) -> None:
    for k in o:
        if k not in fields:
            shown = k if isinstance(k, str) else repr(k)
            names = ", ".join(sorted(fields)) or "none"
            raise ConversionError(
                prefix + shown,
                f"a field of {type_name}",
                detail=f"{type_name} has no field {shown!r} (its fields: {names})",
            )


# --------------------------------------------------------------------------------------------
# The converter


class FromObj(Protocol):
    """Signature of :attr:`Converter.from_obj`."""

    def __call__(self, obj: Any, path: str = "") -> Any:
        """Build a new message from ``obj``; error paths are prefixed with ``path``."""


class Converter:
    """Compiled conversions for one rclpy message class. Get one with :func:`converter_for`."""

    to_obj: Callable[[Any], dict[str, Any]]
    """ROS message -> JSON-ready dict (base64 for uint8 arrays, None for NaN/Inf)."""

    to_cbor_obj: Callable[[Any], dict[str, Any]]
    """ROS message -> dict for cbor2 (bytes and CBORTag typed arrays)."""

    from_obj: FromObj
    """``from_obj(obj, path="")``: decoded JSON object -> new ROS message; ConversionError."""

    def __init__(self, msg_cls: type[Any]) -> None:
        self.msg_cls = msg_cls
        self.type_name = type_name_of(msg_cls)
        names = list(msg_cls.get_fields_and_field_types().keys())
        self._fields = [
            _Field(n, st, msg_cls) for n, st in zip(names, msg_cls.SLOT_TYPES, strict=True)
        ]
        self.fields: tuple[str, ...] = tuple(names)
        self.json_from_cdr: cdr_json.JsonFromCdr | None = None
        """CDR bytes -> the same text as :meth:`to_json` gives, without deserializing
        (:mod:`rosbridge_core.codec.cdr_json`); ``None`` when msgs does not have the type's
        layout."""

    def to_json(self, ros_msg: Any) -> str:
        """Compact JSON text of ``ros_msg`` (the msg object only, no op envelope)."""
        try:
            return self._to_json_text(ros_msg)
        except ValueError:  # a NaN/Inf inside a numeric array: take the careful path
            return _json_encode(self.to_obj(ros_msg))

    def _compile(self) -> None:
        for f in self._fields:
            if f.subclass is not None:
                f.sub = converter_for(f.subclass)
        proto = self.msg_cls()
        ns: dict[str, Any] = {
            "cls": self.msg_cls,
            "new": object.__new__,
            "CHECK_FIELDS": getattr(proto, "_check_fields", False),
            "MISSING": _MISSING,
            "b64_text": cdr_json.b64_text,
            "Tag": _Tag,
            "floats": _floats,
            "octets": _octets,
            "little_endian": _le_bytes,
            "mapping": _mapping,
            "unknown": _unknown,
            "json_encode": _json_encode,
            "json_string": _encode_str,
            "int_text": int.__repr__,
            "float_repr": float.__repr__,
            "float_text": _float_text,
            "int8_text": _int8_text,
            "FIELDS": frozenset(self.fields),
            "TYPE": self.type_name,
            "list": list,
            "map": map,
            "bytes": bytes,
            "range": range,
        }
        json_items: list[str] = []
        cbor_items: list[str] = []
        text_parts: list[tuple[bool, str]] = []
        in_lines: list[str] = []
        for i, f in enumerate(self._fields):
            a = f"m._{f.name}"
            key = repr(f.name)
            j, c = self._out_exprs(f, a, i, ns)
            json_items.append(f"{key}: {j}")
            cbor_items.append(f"{key}: {c}")
            text_parts.append((True, ("," if i else "{") + f'"{f.name}":'))
            text_parts.extend(self._text_parts(f, a, i, ns))
            in_lines.extend(self._in_lines(f, i, ns, proto))
        if not self._fields:
            text_parts.append((True, "{"))
        text_parts.append((True, "}"))

        src = [
            "def to_obj(m):",
            "    return {" + ", ".join(json_items) + "}",
            "def to_cbor_obj(m):",
            "    return {" + ", ".join(cbor_items) + "}",
            "def to_json_text(m):",
            "    return ''.join((" + ", ".join(_merge_literals(text_parts)) + ",))",
            'def from_obj(obj, path=""):',
            "    o = obj",
            "    p = path",
            "    if type(o) is not dict:",
            "        o = mapping(o, p, TYPE)",
            "    n = len(o)",
            "    if not n:",
            "        return cls()",
            "    m = new(cls)",
            "    m._check_fields = CHECK_FIELDS",
            '    pp = p + "." if p else ""',
            "    k = 0",
            "    g = o.get",
            *in_lines,
            "    if k != n:",
            "        unknown(o, FIELDS, pp, TYPE)",
            "    return m",
        ]
        code = "\n".join(src)
        exec(compile(code, f"<converter {self.type_name}>", "exec"), ns)
        self.to_obj = ns["to_obj"]
        self.to_cbor_obj = ns["to_cbor_obj"]
        self._to_json_text: Callable[[Any], str] = ns["to_json_text"]
        from_obj = ns["from_obj"]
        if self.type_name in ("builtin_interfaces/msg/Time", "builtin_interfaces/msg/Duration"):
            from_obj = _time_wrapper(from_obj, self.msg_cls, self.type_name.endswith("/Time"))
        self.from_obj = from_obj
        self._source = code

    @staticmethod
    def _text_parts(f: _Field, a: str, i: int, ns: dict[str, Any]) -> list[tuple[bool, str]]:
        """(is_literal, text) pieces whose concatenation is the JSON text of field value ``a``."""
        e = f.elem
        if f.container is None:
            if e == "bool":
                return [(False, f'("true" if {a} else "false")')]
            if e in _INT_RANGES:
                return [(False, f"int_text({a})")]
            if e in ("float32", "float64"):
                return [(False, f"(float_repr(x) if type(x := {a}) is float and x - x == 0.0 "
                                "else float_text(x))")]
            if e == "octet":
                return [(False, f"int_text({a}[0])")]
            if e == "msg":
                assert f.sub is not None
                ns[f"t{i}"] = f.sub._to_json_text
                return [(False, f"t{i}({a})")]
            return [(False, f"json_string({a})")]  # string, char
        if e == "uint8":
            text = f"b64_text({a})"
            return [(True, '"'), (False, text), (True, '"')]
        if e == "octet":
            return [(False, f"json_encode(octets({a}))")]
        if e == "int8":  # maps (OccupancyGrid) can be huge: a 256-entry text table
            return [(False, f"int8_text({a})")]
        if e in _CBOR_TAGS:
            return [(False, f"json_encode({a}.tolist())")]
        if e == "msg":
            assert f.sub is not None
            ns[f"t{i}"] = f.sub._to_json_text
            return [(True, "["), (False, f'",".join(map(t{i}, {a}))'), (True, "]")]
        return [(False, f"json_encode({a})")]  # bool, string, char arrays (lists)

    @staticmethod
    def _out_exprs(f: _Field, a: str, i: int, ns: dict[str, Any]) -> tuple[str, str]:
        """(JSON expression, CBOR expression) reading attribute expression ``a``."""
        e = f.elem
        if f.container is None:
            if e in ("float32", "float64"):
                return f"(x if (x := {a}) - x == 0.0 else None)", a
            if e == "octet":
                return f"{a}[0]", f"{a}[0]"
            if e == "msg":
                assert f.sub is not None
                ns[f"j{i}"] = f.sub.to_obj
                ns[f"c{i}"] = f.sub.to_cbor_obj
                return f"j{i}({a})", f"c{i}({a})"
            return a, a
        # arrays
        if e == "uint8":
            return f"b64_text({a})", f"bytes({a})"
        if e == "octet":
            return f"octets({a})", f'b"".join({a})'
        if e in _CBOR_TAGS:
            tag = _CBOR_TAGS[e]
            # big-endian hosts swap to little-endian first
            c = (f"Tag({tag}, bytes({a}))" if e == "int8" or _LITTLE
                 else f"Tag({tag}, little_endian({a}))")
            if e in ("float32", "float64"):
                return f"floats({a}.tolist())", c
            return f"{a}.tolist()", c
        if e == "msg":
            assert f.sub is not None
            ns[f"j{i}"] = f.sub.to_obj
            ns[f"c{i}"] = f.sub.to_cbor_obj
            return f"list(map(j{i}, {a}))", f"list(map(c{i}, {a}))"
        # bool, string, char arrays
        return f"list({a})", f"list({a})"

    @staticmethod
    def _default_expr(f: _Field, i: int, ns: dict[str, Any], proto: Any) -> str:
        """Expression giving a fresh default value for field ``f`` (like the constructor)."""
        d = getattr(proto, "_" + f.name)
        ns[f"D{i}"] = d
        if f.container is None:
            if f.elem == "msg":
                ns[f"N{i}"] = f.subclass
                return f"N{i}()"
            return f"D{i}"  # immutable
        if isinstance(d, numpy.ndarray):
            return f"D{i}.copy()"
        if f.elem == "msg":
            ns[f"N{i}"] = f.subclass
            return f"[N{i}() for _ in range({len(d)})]"
        return f"D{i}[:]"  # array.array or list of immutable items

    @staticmethod
    def _in_lines(f: _Field, i: int, ns: dict[str, Any], proto: Any) -> list[str]:
        name = f.name
        key = repr(name)
        slot = f"m._{name}"
        lines = [
            f"    v = g({key}, MISSING)",
            "    if v is MISSING:",
            f"        {slot} = {Converter._default_expr(f, i, ns, proto)}",
            "    else:",
            "        k += 1",
        ]
        e = f.elem
        if f.container is None and e == "msg":
            assert f.sub is not None
            ns[f"s{i}"] = f.sub.from_obj
            lines.append(f"        {slot} = s{i}(v, pp + {key})")
            return lines
        if f.container is None:
            ns[f"v{i}"] = _scalar_checker(f)
            if e in _INT_RANGES:
                lo, hi = _INT_RANGES[e]
                cond = f"type(v) is int and {lo} <= v <= {hi}"
            elif e == "float64":
                cond = "type(v) is float"
            elif e == "float32":
                cond = f"type(v) is float and -{FLOAT32_MAX!r} <= v <= {FLOAT32_MAX!r}"
            elif e == "bool":
                cond = "v is True or v is False"
            elif e == "string" and f.bound is None:
                cond = "type(v) is str"
            else:
                cond = ""
            if cond:
                lines += [
                    f"        if {cond}:",
                    f"            {slot} = v",
                    "        else:",
                    f"            {slot} = v{i}(v, pp + {key})",
                ]
            else:
                lines.append(f"        {slot} = v{i}(v, pp + {key})")
            return lines
        ns[f"v{i}"] = _array_checker(f)
        lines.append(f"        {slot} = v{i}(v, pp + {key})")
        return lines


def _time_wrapper(gen: FromObj, cls: type[Any], is_time: bool) -> FromObj:
    """Time/Duration: accept ROS 1 ``secs``/``nsecs`` keys, and ``"now"`` for Time."""

    def from_obj(obj: Any, path: str = "") -> Any:
        o = obj
        if type(o) is dict and ("secs" in o or "nsecs" in o):
            o = dict(o)
            if "secs" in o:
                v = o.pop("secs")
                o.setdefault("sec", v)
            if "nsecs" in o:
                v = o.pop("nsecs")
                o.setdefault("nanosec", v)
        elif is_time and o == "now":
            t = now_ns()
            m = cls()
            m.sec, m.nanosec = divmod(t, 1_000_000_000)
            return m
        return gen(o, path)

    return from_obj


_converters: dict[type[Any], Converter] = {}
_lock = threading.RLock()


def converter_for(msg_cls: type[Any]) -> Converter:
    """The compiled :class:`Converter` for an rclpy message class (built once, cached)."""
    conv = _converters.get(msg_cls)
    if conv is not None:
        return conv
    with _lock:
        conv = _converters.get(msg_cls)
        if conv is None:
            conv = Converter(msg_cls)
            conv._compile()
            conv.json_from_cdr = cdr_json.encoder_for(msg_cls, conv.type_name)
            _converters[msg_cls] = conv
    return conv


# --------------------------------------------------------------------------------------------
# Whole-op encoders



def serialize(ros_msg: Any) -> bytes:
    """CDR bytes of an rclpy message (``rclpy.serialization.serialize_message``)."""
    from rclpy.serialization import serialize_message

    data: bytes = serialize_message(ros_msg)
    return data


def deserialize(data: bytes, msg_cls: type[Any]) -> Any:
    """An rclpy message from CDR bytes (``rclpy.serialization.deserialize_message``)."""
    from rclpy.serialization import deserialize_message

    return deserialize_message(data, msg_cls)
