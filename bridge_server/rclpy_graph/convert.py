"""ROS message <-> rosbridge JSON / CBOR conversion, compiled once per message type.

``converter_for(cls)`` walks a message class's ``SLOT_TYPES`` a single time
and generates specialised Python functions (with ``exec``) for the three hot
paths. The result is cached per class, so every later call is one dict lookup.
Each field is classified once (:mod:`.fields`); what a client sends is checked by the
validators of :mod:`.validate`.

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
import json
import sys
import threading
import time
from collections.abc import Callable, Mapping
from typing import Any, Final

import cbor2
import numpy

from bridge_server.allocator import tune_allocator
from bridge_server.rclpy_graph.fields import INT_RANGES, Field, FromObj
from bridge_server.rclpy_graph.types import type_name_of
from bridge_server.rclpy_graph.validate import array_checker, scalar_checker
from msgs._primitives import FLOAT32_MAX
from rosbridge_core.codec import cdr_json
from rosbridge_core.codec.publish import (
    encode_publish_cbor,
    encode_publish_cbor_raw,
    encode_publish_json,
)
from rosbridge_core.interfaces import MISSING as _MISSING
from rosbridge_core.interfaces import ConversionError, args_mapping

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
_Tag = cbor2.CBORTag
_cbor_dumps: Callable[[Any], bytes] = cbor2.dumps


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
            Field(n, st, msg_cls) for n, st in zip(names, msg_cls.SLOT_TYPES, strict=True)
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
    def _text_parts(f: Field, a: str, i: int, ns: dict[str, Any]) -> list[tuple[bool, str]]:
        """(is_literal, text) pieces whose concatenation is the JSON text of field value ``a``."""
        e = f.elem
        if f.container is None:
            if e == "bool":
                return [(False, f'("true" if {a} else "false")')]
            if e in INT_RANGES:
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
    def _out_exprs(f: Field, a: str, i: int, ns: dict[str, Any]) -> tuple[str, str]:
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
    def _default_expr(f: Field, i: int, ns: dict[str, Any], proto: Any) -> str:
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
    def _in_lines(f: Field, i: int, ns: dict[str, Any], proto: Any) -> list[str]:
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
            ns[f"v{i}"] = scalar_checker(f)
            if e in INT_RANGES:
                lo, hi = INT_RANGES[e]
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
        ns[f"v{i}"] = array_checker(f)
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
