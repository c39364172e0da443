"""Conversion of scalars and strings, ROS message <-> rosbridge JSON/CBOR, with real rclpy classes.

bridge_server.rclpy_graph.convert: integer, float, bool and byte ranges, NaN, string bounds.
"""

from __future__ import annotations

import math
from typing import Any

import numpy
import pytest

from bridge_server.rclpy_graph.convert import (
    ConversionError,
    converter_for,
    deserialize,
    serialize,
)
from bridge_server.rclpy_graph.validate import string_checker
from tests.bridge.convert_support import (
    error_of,
    strict_loads,
    via_cbor,
    via_json,
)

# --------------------------------------------------------------------------------------------
# scalars

INT_EDGES = [
    ("int8_value", "int8", -128, 127),
    ("uint8_value", "uint8", 0, 255),
    ("char_value", "uint8", 0, 255),
    ("int16_value", "int16", -32768, 32767),
    ("uint16_value", "uint16", 0, 65535),
    ("int32_value", "int32", -(2**31), 2**31 - 1),
    ("uint32_value", "uint32", 0, 2**32 - 1),
    ("int64_value", "int64", -(2**63), 2**63 - 1),
    ("uint64_value", "uint64", 0, 2**64 - 1),
]


@pytest.mark.parametrize(("field", "typ", "lo", "hi"), INT_EDGES)
def test_integer_range_edges_accepted(field: str, typ: str, lo: int, hi: int) -> None:
    """The smallest and largest value of each integer type go in and come back out unchanged."""
    from test_msgs.msg import BasicTypes

    conv = converter_for(BasicTypes)
    for v in (lo, hi):
        msg = conv.from_obj({field: v})
        assert getattr(msg, field) == v
        assert strict_loads(conv.to_json(msg))[field] == v
        assert deserialize(serialize(msg), BasicTypes) == msg


@pytest.mark.parametrize(("field", "typ", "lo", "hi"), INT_EDGES)
def test_integer_out_of_range_names_field_and_type(field: str, typ: str, lo: int, hi: int) -> None:
    """One past either end of an integer type is an error naming the field and the type."""
    from test_msgs.msg import BasicTypes

    conv = converter_for(BasicTypes)
    for v in (lo - 1, hi + 1):
        err = error_of(conv, {field: v})
        assert err.path == field
        assert err.expected == typ
        assert "out of range" in str(err)
        assert field in str(err)


@pytest.mark.parametrize("bad", [True, False, "1", 1.5, None, [1], {"a": 1}])
def test_integer_rejects_other_kinds(bad: Any) -> None:
    """Integer fields reject bools, strings, fractional floats, null, arrays and objects."""
    from test_msgs.msg import BasicTypes

    err = error_of(converter_for(BasicTypes), {"int32_value": bad})
    assert err.path == "int32_value"
    assert err.expected == "int32"
    assert "expected int32" in str(err)


def test_integer_accepts_integral_float() -> None:
    """A float with an integral value (3.0, 1e3) is accepted for an integer field, as an int."""
    from test_msgs.msg import BasicTypes

    conv = converter_for(BasicTypes)
    msg = conv.from_obj({"int32_value": 3.0, "uint64_value": 1e3})
    assert msg.int32_value == 3 and type(msg.int32_value) is int
    assert msg.uint64_value == 1000 and type(msg.uint64_value) is int
    assert error_of(conv, {"uint8_value": 256.0}).path == "uint8_value"


def test_float_fields_accept_ints_and_keep_floats() -> None:
    """Float fields take JSON ints (as the reference does) and floats."""
    from test_msgs.msg import BasicTypes

    conv = converter_for(BasicTypes)
    msg = conv.from_obj({"float64_value": 2, "float32_value": 1.5})
    assert msg.float64_value == 2.0 and type(msg.float64_value) is float
    assert msg.float32_value == 1.5
    out = strict_loads(conv.to_json(msg))
    assert out["float64_value"] == 2.0
    assert deserialize(serialize(msg), BasicTypes) == msg


@pytest.mark.parametrize("bad", [True, "1.0", [1.0], {}])
def test_float_rejects_other_kinds(bad: Any) -> None:
    """Float fields reject bools, strings, arrays and objects, naming the type."""
    from test_msgs.msg import BasicTypes

    err = error_of(converter_for(BasicTypes), {"float64_value": bad})
    assert err.path == "float64_value"
    assert err.expected == "float64"


def test_float32_range() -> None:
    """float32 takes its largest finite value and infinities, but not finite values beyond it."""
    from test_msgs.msg import BasicTypes

    conv = converter_for(BasicTypes)
    flt_max = float(numpy.finfo(numpy.float32).max)
    assert conv.from_obj({"float32_value": flt_max}).float32_value == flt_max
    assert conv.from_obj({"float32_value": -flt_max}).float32_value == -flt_max
    assert conv.from_obj({"float32_value": 2**100}).float32_value == 2.0**100
    for bad in (3.5e38, -1e39, 10**39):
        err = error_of(conv, {"float32_value": bad})
        assert err.path == "float32_value" and err.expected == "float32"
        assert "out of range" in str(err)
    assert error_of(conv, {"float64_value": 10**400}).expected == "float64"
    assert conv.from_obj({"float64_value": 1e308}).float64_value == 1e308


def test_nan_and_infinity_go_out_as_null_and_null_comes_in_as_nan() -> None:
    """NaN/±Inf become JSON null (scalar fields); null for a float field means NaN."""
    from test_msgs.msg import BasicTypes

    conv = converter_for(BasicTypes)
    msg = BasicTypes(float64_value=math.nan, float32_value=math.inf)
    out = strict_loads(conv.to_json(msg))
    assert out["float64_value"] is None and out["float32_value"] is None
    assert conv.to_obj(msg)["float64_value"] is None
    msg.float64_value = -math.inf
    assert strict_loads(conv.to_json(msg))["float64_value"] is None
    back = conv.from_obj({"float64_value": None, "float32_value": None})
    assert math.isnan(back.float64_value) and math.isnan(back.float32_value)


def test_nan_inside_arrays_goes_out_as_null() -> None:
    """NaN/Inf items of fixed and variable float arrays become null; null items come in as NaN."""
    from test_msgs.msg import Arrays, UnboundedSequences

    conv = converter_for(UnboundedSequences)
    msg = UnboundedSequences(float64_values=[1.0, math.nan, -math.inf], float32_values=[math.inf])
    out = strict_loads(conv.to_json(msg))
    assert out["float64_values"] == [1.0, None, None]
    assert out["float32_values"] == [None]
    back = conv.from_obj({"float64_values": [None, 2], "float32_values": [None]})
    assert math.isnan(back.float64_values[0]) and back.float64_values[1] == 2.0
    assert math.isnan(back.float32_values[0])

    aconv = converter_for(Arrays)
    amsg = Arrays(float32_values=[0.5, math.nan, math.inf])
    assert strict_loads(aconv.to_json(amsg))["float32_values"] == [0.5, None, None]
    assert aconv.to_obj(amsg)["float32_values"] == [0.5, None, None]


def test_bool_accepts_only_true_and_false() -> None:
    """bool fields take only JSON true/false, not 0/1 or strings."""
    from test_msgs.msg import BasicTypes

    conv = converter_for(BasicTypes)
    assert conv.from_obj({"bool_value": True}).bool_value is True
    assert strict_loads(conv.to_json(BasicTypes(bool_value=True)))["bool_value"] is True
    for bad in (1, 0, "true", None):
        err = error_of(conv, {"bool_value": bad})
        assert err.path == "bool_value" and err.expected == "bool"


def test_byte_scalar_is_an_integer() -> None:
    """A byte (octet) field goes out as an int and takes ints 0..255."""
    from test_msgs.msg import BasicTypes

    conv = converter_for(BasicTypes)
    msg = conv.from_obj({"byte_value": 255})
    assert msg.byte_value == b"\xff"
    assert strict_loads(conv.to_json(msg))["byte_value"] == 255
    assert conv.to_cbor_obj(msg)["byte_value"] == 255
    for bad in (256, -1, True, "a"):
        assert error_of(conv, {"byte_value": bad}).path == "byte_value"
    assert deserialize(serialize(msg), BasicTypes) == msg


# --------------------------------------------------------------------------------------------
# strings


def test_strings_round_trip_including_unicode() -> None:
    """Unbounded and bounded strings, with non-ASCII text and JSON-special characters."""
    from test_msgs.msg import Strings, WStrings

    conv = converter_for(Strings)
    text = 'héllo "quoted" \\ back\nslash \u2603 \U0001f600'
    msg = conv.from_obj({"string_value": text, "bounded_string_value": "short"})
    assert msg.string_value == text
    assert via_json(conv, msg) == msg
    assert via_cbor(conv, msg) == msg
    assert deserialize(serialize(msg), Strings) == msg

    wconv = converter_for(WStrings)
    wmsg = wconv.from_obj({"wstring_value": text, "array_of_wstrings": ["a", "\u2603", ""]})
    assert via_json(wconv, wmsg) == wmsg
    assert deserialize(serialize(wmsg), WStrings) == wmsg


def test_bounded_string_limits_count_utf8_bytes() -> None:
    """string<=22 takes 22 bytes and rejects 23, counting UTF-8 bytes of non-ASCII text."""
    from test_msgs.msg import Strings

    conv = converter_for(Strings)
    assert conv.from_obj({"bounded_string_value": "x" * 22}).bounded_string_value == "x" * 22
    assert conv.from_obj({"bounded_string_value": "é" * 11}).bounded_string_value == "é" * 11
    for bad in ("x" * 23, "é" * 12):
        err = error_of(conv, {"bounded_string_value": bad})
        assert err.path == "bounded_string_value"
        assert err.expected == "string<=22"
        assert "exceeds" in str(err)


def test_bounded_wstring_limit_counts_characters() -> None:
    """wstring<=N bounds count characters, string<=N bounds count UTF-8 bytes."""
    wcheck = string_checker(3, "wstring<=3", True)
    assert wcheck("ééé", "w") == "ééé"
    with pytest.raises(ConversionError, match="4 characters exceeds the bound wstring<=3"):
        wcheck("abcd", "w")
    check = string_checker(3, "string<=3", False)
    with pytest.raises(ConversionError, match="4 bytes exceeds the bound string<=3"):
        check("éé", "s")


def test_string_rejects_other_kinds() -> None:
    """String fields reject numbers, null and arrays."""
    from test_msgs.msg import Strings

    conv = converter_for(Strings)
    for bad in (1, None, ["a"], True):
        err = error_of(conv, {"string_value": bad})
        assert err.path == "string_value" and err.expected == "string"


def test_error_message_does_not_carry_the_payload() -> None:
    """A huge wrong value is described briefly in the error, never copied whole."""
    from test_msgs.msg import BasicTypes

    err = error_of(converter_for(BasicTypes), {"int32_value": "z" * 100_000})
    assert len(str(err)) < 300
    assert "100000 characters" in str(err)
