"""The inbound validators of :mod:`.convert` (JSON -> ROS): per field, ``(value, path) ->
stored value`` or :class:`~rosbridge_core.interfaces.ConversionError` naming the path, what
was expected and what came. The generated ``from_obj`` calls them where its inline fast
checks do not settle a value."""

from __future__ import annotations

import array
import binascii
from collections.abc import Callable
from typing import Any, Final

import numpy

from bridge_server.rclpy_graph.fields import INT_RANGES, Field
from msgs._primitives import FLOAT32_MAX
from rosbridge_core.interfaces import ConversionError
from rosbridge_core.interfaces import describe as _describe

__all__ = ["array_checker", "scalar_checker", "string_checker"]

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
_a2b = binascii.a2b_base64


# --------------------------------------------------------------------------------------------
# Inbound scalar validators: (value, path) -> stored value, or raise ConversionError


def _int_checker(name: str) -> Callable[[Any, str], int]:
    lo, hi = INT_RANGES[name]

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


def string_checker(bound: int | None, expected: str, wide: bool) -> Callable[[Any, str], str]:
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


def scalar_checker(f: Field) -> Callable[[Any, str], Any]:
    e = f.elem
    if e == "bool":
        return _bool_check
    if e == "octet":
        return _octet_check
    if e == "char":
        return _char_check
    if e == "string":
        return string_checker(f.bound, f.elem_name, f.wide)
    if e in ("float32", "float64"):
        return _float_checker(e)
    return _int_checker(e)


# --------------------------------------------------------------------------------------------
# Inbound array validators


def _elem_path(path: str, i: int) -> str:
    return f"{path}[{i}]"


def _check_len(f: Field, n: int, path: str, v: object) -> None:
    """Fixed arrays need exactly ``size`` items, bounded sequences at most ``size``."""
    if (f.container == "array" and n != f.size) or (f.container == "bseq" and n > f.size):
        raise ConversionError(path, f.expected(), v, f"expected {f.expected()}, got {n} items")


def _decode_binary(f: Field, v: Any, path: str) -> bytes:
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


def array_checker(f: Field) -> Callable[[Any, str], Any]:
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

    if e in INT_RANGES:
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
        scheck = scalar_checker(f)
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
