"""Each field's checker, converter and JSON encoder, made from its type string in rclpy's
spelling (``int32``, ``string<10>``, ``sequence<double, 3>``, ``std_msgs/Header``, ...): the
parts :class:`msgs._message.Message` builds its class's codec from."""

from __future__ import annotations

import array
import base64
import binascii
import math
import re
from collections.abc import Callable, Mapping
from typing import Any, Protocol, Self

from ._errors import ValidationError, _describe
from ._primitives import FLOAT32_MAX, INTEGER_RANGES, SIZED_INTEGER_RANGES

_INT_RANGES = {"octet": INTEGER_RANGES["byte"], **SIZED_INTEGER_RANGES}
"""The integer types by rclpy's names for them."""
# The .msg spelling of rclpy's type names, for error messages.
_MSG_NAMES = {"boolean": "bool", "octet": "byte", "float": "float32", "double": "float64"}


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


class _Nested(Protocol):
    """What a nested message field's converter uses of the field's class (a
    :class:`msgs._message.Message`, whose module builds on this one)."""

    def validate(self) -> None:
        """Check every field's value."""

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Self:
        """Build one from its wire form."""


_FindNested = Callable[[str], type[_Nested]]


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


def _nested_conv(type_name: str, wire: bool, deep: bool, find: _FindNested) -> _Conv:
    cls_box: list[type[_Nested]] = []

    def conv(value: Any) -> _Nested:
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


def _scalar_conv(idl: str, wire: bool, deep: bool, find: _FindNested) -> _Conv:
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


def _field_conv(idl: str, wire: bool, find: _FindNested, deep: bool = True) -> _Conv:
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
