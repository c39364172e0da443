"""ROS message <-> rosbridge JSON/CBOR conversion (bridge_server.rclpy_graph.convert) with real rclpy classes."""

from __future__ import annotations

import array
import base64
import json
import math
import struct
import sys
import types
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cbor2
import numpy
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rosidl_parser import definition as idl

import bridge_server.rclpy_graph.convert as convert_mod
from bridge_server.rclpy_graph.convert import (
    ConversionError,
    Converter,
    converter_for,
    deserialize,
    encode_publish_cbor,
    encode_publish_cbor_raw,
    encode_publish_json,
    serialize,
)
from bridge_server.rclpy_graph.types import BridgeError
from bridge_server.rclpy_graph.validate import string_checker

# rclpy's type-support import pulls in lark, which imports the deprecated sre_* modules;
# warnings are errors in this suite, so load it once here with that one warning silenced.
with warnings.catch_warnings():
    warnings.filterwarnings("ignore", "module 'sre_.*' is deprecated", DeprecationWarning)
    import rosidl_generator_py  # noqa: F401

# --------------------------------------------------------------------------------------------
# helpers


def strict_loads(text: str) -> Any:
    """json.loads that refuses NaN/Infinity tokens (they are not JSON)."""

    def bad(token: str) -> Any:
        raise AssertionError(f"non-JSON token {token} in output")

    return json.loads(text, parse_constant=bad)


def via_json(conv: Converter, msg: Any) -> Any:
    """ROS msg -> JSON text -> parsed -> ROS msg."""
    return conv.from_obj(strict_loads(conv.to_json(msg)))


_TYPECODE_OF_TAG = {69: "H", 70: "I", 71: "Q", 72: "b", 77: "h", 78: "i", 79: "q", 85: "f", 86: "d"}


def untag(obj: Any) -> Any:
    """Turn decoded CBOR typed arrays back into lists (what a client does)."""
    if isinstance(obj, cbor2.CBORTag):
        code = _TYPECODE_OF_TAG[obj.tag]
        arr = array.array(code)
        arr.frombytes(obj.value)
        if sys.byteorder != "little":
            arr.byteswap()
        return arr.tolist()
    if isinstance(obj, dict):
        return {k: untag(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [untag(v) for v in obj]
    return obj


def via_cbor(conv: Converter, msg: Any) -> Any:
    """ROS msg -> whole CBOR publish op -> decoded -> typed arrays untagged -> ROS msg."""
    op = cbor2.loads(encode_publish_cbor("/t", msg, conv))
    assert op["op"] == "publish"
    assert op["topic"] == "/t"
    return conv.from_obj(untag(op["msg"]))


def error_of(conv: Converter, obj: Any) -> ConversionError:
    """The ConversionError that from_obj raises for obj."""
    with pytest.raises(ConversionError) as info:
        conv.from_obj(obj)
    return info.value


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


# --------------------------------------------------------------------------------------------
# arrays

NUMERIC: dict[str, tuple[str, list[Any], list[Any]]] = {
    "int8_values": ("int8", [-128, 0, 127], [-129]),
    "int16_values": ("int16", [-32768, 0, 32767], [32768]),
    "uint16_values": ("uint16", [0, 1, 65535], [-1]),
    "int32_values": ("int32", [-(2**31), 0, 2**31 - 1], [2**31]),
    "uint32_values": ("uint32", [0, 1, 2**32 - 1], [2**32]),
    "int64_values": ("int64", [-(2**63), 0, 2**63 - 1], [2**63]),
    "uint64_values": ("uint64", [0, 1, 2**64 - 1], [-1]),
    "float32_values": ("float32", [-1.5, 0.0, 3.25], [1e39]),
    "float64_values": ("float64", [-1e300, 0.0, 1e-300], ["x"]),
}


@pytest.mark.parametrize("cls_name", ["Arrays", "BoundedSequences", "UnboundedSequences"])
@pytest.mark.parametrize("field", sorted(NUMERIC))
def test_numeric_arrays_round_trip_with_rclpy_storage(cls_name: str, field: str) -> None:
    """Numeric arrays of each kind convert both ways and are stored as rclpy stores them."""
    import test_msgs.msg

    cls = getattr(test_msgs.msg, cls_name)
    conv = converter_for(cls)
    _, good, _ = NUMERIC[field]
    msg = conv.from_obj({field: good})
    stored = getattr(msg, field)
    if cls_name == "Arrays":
        assert isinstance(stored, numpy.ndarray)
        assert stored.dtype == getattr(cls(), field).dtype
    else:
        assert isinstance(stored, array.array)
        assert stored.typecode == getattr(cls(), field).typecode
    assert list(stored) == good
    assert strict_loads(conv.to_json(msg))[field] == good
    assert via_json(conv, msg) == msg
    assert via_cbor(conv, msg) == msg
    assert deserialize(serialize(msg), cls) == msg


@pytest.mark.parametrize("cls_name", ["Arrays", "BoundedSequences", "UnboundedSequences"])
@pytest.mark.parametrize("field", sorted(NUMERIC))
def test_numeric_array_item_errors_name_the_index(cls_name: str, field: str) -> None:
    """A bad item is reported at `field[i]` with the item type."""
    import test_msgs.msg

    conv = converter_for(getattr(test_msgs.msg, cls_name))
    typ, good, bad = NUMERIC[field]
    value = [good[0], good[1], bad[0]]
    err = error_of(conv, {field: value})
    assert err.path == f"{field}[2]"
    assert err.expected == typ
    err = error_of(conv, {field: [good[0], True, good[2]]})
    assert err.path == f"{field}[1]"


@pytest.mark.parametrize("field", ["int32_values", "float64_values", "bool_values", "string_values"])
def test_fixed_and_bounded_lengths(field: str) -> None:
    """Fixed arrays need exactly N items, bounded ones at most N; the error names the field."""
    from test_msgs.msg import Arrays, BoundedSequences, UnboundedSequences

    sample = {"int32_values": 1, "float64_values": 1.0, "bool_values": True, "string_values": "s"}[
        field
    ]
    fixed = converter_for(Arrays)
    for n in (2, 4, 0):
        err = error_of(fixed, {field: [sample] * n})
        assert err.path == field
        assert "array of 3" in err.expected
        assert f"got {n} items" in str(err)
    bounded = converter_for(BoundedSequences)
    assert len(getattr(bounded.from_obj({field: [sample] * 3}), field)) == 3
    assert len(getattr(bounded.from_obj({field: []}), field)) == 0
    err = error_of(bounded, {field: [sample] * 4})
    assert err.path == field and "at most 3" in err.expected
    unbounded = converter_for(UnboundedSequences)
    assert len(getattr(unbounded.from_obj({field: [sample] * 1000}), field)) == 1000


@pytest.mark.parametrize("cls_name", ["Arrays", "BoundedSequences", "UnboundedSequences"])
def test_bool_and_string_arrays(cls_name: str) -> None:
    """Bool and string arrays are plain lists both in JSON and in CBOR; bad items name the index."""
    import test_msgs.msg

    cls = getattr(test_msgs.msg, cls_name)
    conv = converter_for(cls)
    msg = conv.from_obj({"bool_values": [True, False, True], "string_values": ["a", "é", ""]})
    assert msg.bool_values == [True, False, True]
    assert msg.string_values == ["a", "é", ""]
    out = strict_loads(conv.to_json(msg))
    assert out["bool_values"] == [True, False, True]
    cb = cbor2.loads(cbor2.dumps(conv.to_cbor_obj(msg)))
    assert cb["bool_values"] == [True, False, True]
    assert cb["string_values"] == ["a", "é", ""]
    assert via_json(conv, msg) == msg
    assert deserialize(serialize(msg), cls) == msg
    assert error_of(conv, {"bool_values": [True, 1, False]}).path == "bool_values[1]"
    assert error_of(conv, {"string_values": ["a", "b", 3]}).path == "string_values[2]"
    assert error_of(conv, {"bool_values": "true"}).path == "bool_values"


# --------------------------------------------------------------------------------------------
# uint8[] / char[] / byte[]


@pytest.mark.parametrize("cls_name", ["Arrays", "BoundedSequences", "UnboundedSequences"])
@pytest.mark.parametrize("field", ["uint8_values", "char_values"])
def test_uint8_and_char_arrays_are_base64(cls_name: str, field: str) -> None:
    """uint8[]/char[] of every kind go out as base64 and come in as base64, int lists or bytes."""
    import test_msgs.msg

    cls = getattr(test_msgs.msg, cls_name)
    conv = converter_for(cls)
    raw = bytes([0, 200, 255])
    b64 = base64.b64encode(raw).decode()
    for value in (b64, list(raw), raw, bytearray(raw)):
        msg = conv.from_obj({field: value})
        assert bytes(getattr(msg, field)) == raw
        assert strict_loads(conv.to_json(msg))[field] == b64
        assert conv.to_obj(msg)[field] == b64
        assert conv.to_cbor_obj(msg)[field] == raw
        assert deserialize(serialize(msg), cls) == msg
    stored = getattr(conv.from_obj({field: b64}), field)
    if cls_name == "Arrays":
        assert isinstance(stored, numpy.ndarray) and stored.dtype == numpy.uint8
    else:
        assert isinstance(stored, array.array) and stored.typecode == "B"


def test_uint8_array_errors() -> None:
    """Bad base64, out-of-range or non-int items and wrong lengths are errors naming the field."""
    from sensor_msgs.msg import Image
    from test_msgs.msg import Arrays, BoundedSequences

    conv = converter_for(Image)
    err = error_of(conv, {"data": "not base64!"})
    assert err.path == "data" and "base64" in str(err)
    assert error_of(conv, {"data": [1, 256]}).path == "data[1]"
    assert error_of(conv, {"data": [1, -1]}).path == "data[1]"
    assert error_of(conv, {"data": [1, True]}).path == "data[1]"
    assert error_of(conv, {"data": [1, 2.5]}).path == "data[1]"
    assert error_of(conv, {"data": 5}).path == "data"
    assert error_of(conv, {"data": None}).path == "data"
    fixed = converter_for(Arrays)
    err = error_of(fixed, {"uint8_values": base64.b64encode(b"ab").decode()})
    assert err.path == "uint8_values" and "got 2 items" in str(err)
    assert error_of(converter_for(BoundedSequences), {"uint8_values": [1, 2, 3, 4]}).path == (
        "uint8_values"
    )


def test_base64_with_line_breaks_is_accepted() -> None:
    """MIME-style base64 (with newlines, as base64.encodebytes makes) is accepted."""
    from sensor_msgs.msg import Image

    raw = bytes(range(256)) * 2
    msg = converter_for(Image).from_obj({"data": base64.encodebytes(raw).decode()})
    assert bytes(msg.data) == raw


@pytest.mark.parametrize("cls_name", ["Arrays", "BoundedSequences", "UnboundedSequences"])
def test_byte_arrays_are_int_lists_in_json_and_bytes_in_cbor(cls_name: str) -> None:
    """byte[] (octet) goes out as a list of ints in JSON and a byte string in CBOR."""
    import test_msgs.msg

    cls = getattr(test_msgs.msg, cls_name)
    conv = converter_for(cls)
    msg = conv.from_obj({"byte_values": [0, 7, 255]})
    assert msg.byte_values == [b"\x00", b"\x07", b"\xff"]
    assert strict_loads(conv.to_json(msg))["byte_values"] == [0, 7, 255]
    assert conv.to_cbor_obj(msg)["byte_values"] == b"\x00\x07\xff"
    assert via_cbor(conv, msg) == msg
    assert deserialize(serialize(msg), cls) == msg
    assert error_of(conv, {"byte_values": [0, 256, 1]}).path == "byte_values[1]"


def test_image_640x480_round_trips_json_and_cbor() -> None:
    """A full 640x480 rgb8 Image survives JSON (base64) and CBOR (byte string) both ways."""
    from sensor_msgs.msg import Image

    conv = converter_for(Image)
    img = Image(height=480, width=640, encoding="rgb8", step=1920)
    img.data = bytes(range(256)) * 3600
    text = encode_publish_json("/camera", conv.to_json(img))
    op = strict_loads(text)
    assert op["op"] == "publish" and op["topic"] == "/camera"
    assert base64.b64decode(op["msg"]["data"]) == bytes(img.data)
    assert conv.from_obj(op["msg"]) == img
    assert via_cbor(conv, img) == img


# --------------------------------------------------------------------------------------------
# nested messages, paths, defaults


def test_nested_error_paths_inside_arrays_of_messages() -> None:
    """A wrong value deep inside an array of messages names the full path."""
    from nav_msgs.msg import Path as PathMsg

    conv = converter_for(PathMsg)
    poses: list[Any] = [{}, {}, {"pose": {"position": {"x": "far"}}}]
    err = error_of(conv, {"poses": poses})
    assert err.path == "poses[2].pose.position.x"
    assert err.expected == "float64"
    assert str(err).startswith("poses[2].pose.position.x: expected float64, got string 'far'")
    err = error_of(conv, {"poses": [{}, {"header": {"stamp": {"sec": 2**31}}}]})
    assert err.path == "poses[1].header.stamp.sec"
    assert err.expected == "int32"


def test_unknown_field_names_the_path_and_the_type() -> None:
    """A key the type lacks is an error naming its full path and the message type."""
    from geometry_msgs.msg import PoseStamped

    conv = converter_for(PoseStamped)
    err = error_of(conv, {"pose": {"position": {"x": 1.0, "w": 2.0}}})
    assert err.path == "pose.position.w"
    assert "geometry_msgs/msg/Point" in str(err)
    assert "'w'" in str(err)
    err = error_of(conv, {"header": {}, "extra": 1})
    assert err.path == "extra"
    assert "geometry_msgs/msg/PoseStamped" in str(err)


def test_non_object_for_a_message_is_an_error() -> None:
    """A message must be a JSON object, at the top and at every nested field."""
    from geometry_msgs.msg import PoseStamped

    conv = converter_for(PoseStamped)
    err = error_of(conv, {"header": 5})
    assert err.path == "header"
    assert err.expected == "object of type std_msgs/msg/Header"
    err = error_of(conv, [1, 2])
    assert err.path == ""
    assert "object of type geometry_msgs/msg/PoseStamped" in str(err)


def test_path_prefix_is_used_in_errors() -> None:
    """from_obj(obj, path) prefixes the reported paths (e.g. with 'msg' or 'args')."""
    from geometry_msgs.msg import Point

    err = converter_for(Point)
    with pytest.raises(ConversionError) as info:
        err.from_obj({"x": "a"}, "args")
    assert info.value.path == "args.x"


def test_missing_fields_keep_defaults() -> None:
    """Fields absent from the object keep the type's defaults, including non-zero defaults."""
    from test_msgs.msg import Arrays, Defaults, MultiNested

    conv = converter_for(Defaults)
    msg = conv.from_obj({"int8_value": 1})
    expected = Defaults()
    expected.int8_value = 1
    assert msg == expected
    assert Defaults().int16_value != 0  # the type really has non-zero defaults
    assert converter_for(Arrays).from_obj({"alignment_check": 3}).bool_values_default == (
        Arrays().bool_values_default
    )
    mn = converter_for(MultiNested).from_obj({"unbounded_sequence_of_arrays": [{}]})
    assert mn.unbounded_sequence_of_arrays == [Arrays()]
    assert mn.array_of_arrays == MultiNested().array_of_arrays


def test_defaults_are_fresh_objects() -> None:
    """Two converted messages never share mutable default values."""
    from test_msgs.msg import Arrays

    conv = converter_for(Arrays)
    a = conv.from_obj({"alignment_check": 1})
    b = conv.from_obj({"alignment_check": 2})
    a.int32_values[0] = 99
    a.basic_types_values[0].int8_value = 5
    a.bool_values[0] = True
    assert b.int32_values[0] == 0
    assert b.basic_types_values[0].int8_value == 0
    assert b.bool_values[0] is False


def test_any_mapping_is_accepted() -> None:
    """A read-only Mapping works as well as a dict."""
    from geometry_msgs.msg import Point

    msg = converter_for(Point).from_obj(types.MappingProxyType({"x": 1.0}))
    assert msg.x == 1.0


# --------------------------------------------------------------------------------------------
# Time / Duration


def test_time_and_duration_are_plain_messages() -> None:
    """Time and Duration are {"sec", "nanosec"} both ways, with their int ranges."""
    from builtin_interfaces.msg import Duration, Time
    from std_msgs.msg import Header

    conv = converter_for(Header)
    msg = conv.from_obj({"stamp": {"sec": 12, "nanosec": 345}, "frame_id": "map"})
    assert msg.stamp == Time(sec=12, nanosec=345)
    assert strict_loads(conv.to_json(msg)) == {
        "stamp": {"sec": 12, "nanosec": 345},
        "frame_id": "map",
    }
    dconv = converter_for(Duration)
    assert dconv.from_obj({"sec": -5, "nanosec": 1}) == Duration(sec=-5, nanosec=1)
    assert error_of(conv, {"stamp": {"nanosec": -1}}).path == "stamp.nanosec"
    assert error_of(conv, {"stamp": {"sec": 2**31}}).expected == "int32"


def test_time_accepts_ros1_keys_and_now(monkeypatch: pytest.MonkeyPatch) -> None:
    """Time/Duration accept secs/nsecs (ROS 1 style); a Time may be "now"."""
    from builtin_interfaces.msg import Duration, Time
    from std_msgs.msg import Header

    assert converter_for(Time).from_obj({"secs": 3, "nsecs": 4}) == Time(sec=3, nanosec=4)
    assert converter_for(Duration).from_obj({"secs": 1}) == Duration(sec=1)
    monkeypatch.setattr(convert_mod, "now_ns", lambda: 7_000_000_008)
    assert converter_for(Header).from_obj({"stamp": "now"}).stamp == Time(sec=7, nanosec=8)
    assert error_of(converter_for(Duration), "now").path == ""


# --------------------------------------------------------------------------------------------
# CBOR


def test_cbor_typed_arrays_use_rfc8746_little_endian_tags() -> None:
    """Numeric arrays become tagged little-endian byte strings; uint8[] a plain byte string."""
    from test_msgs.msg import Arrays, UnboundedSequences

    expected = {
        "uint16_values": (69, "<H"),
        "uint32_values": (70, "<I"),
        "uint64_values": (71, "<Q"),
        "int8_values": (72, "<b"),
        "int16_values": (77, "<h"),
        "int32_values": (78, "<i"),
        "int64_values": (79, "<q"),
        "float32_values": (85, "<f"),
        "float64_values": (86, "<d"),
    }
    for cls in (UnboundedSequences, Arrays):
        conv = converter_for(cls)
        values = {f: NUMERIC[f][1] for f in expected}
        msg = conv.from_obj({**values, "uint8_values": [1, 2, 3], "bool_values": [True] * 3})
        op = cbor2.loads(encode_publish_cbor("/arr", msg, conv))
        assert op["op"] == "publish" and op["topic"] == "/arr"
        m = op["msg"]
        for field, (tag, fmt) in expected.items():
            item = m[field]
            assert isinstance(item, cbor2.CBORTag), field
            assert item.tag == tag, field
            assert item.value == struct.pack(f"<{len(values[field])}{fmt[1]}", *values[field])
        assert m["uint8_values"] == b"\x01\x02\x03"
        assert m["bool_values"] == [True, True, True]
        assert m["string_values"] == list(msg.string_values)


def test_cbor_keeps_nan_and_infinity() -> None:
    """CBOR carries NaN and infinities as floats (no null needed)."""
    from test_msgs.msg import BasicTypes

    conv = converter_for(BasicTypes)
    msg = BasicTypes(float64_value=math.nan, float32_value=-math.inf)
    m = cbor2.loads(encode_publish_cbor("/f", msg, conv))["msg"]
    assert math.isnan(m["float64_value"]) and m["float32_value"] == -math.inf


def test_cbor_raw_carries_cdr_that_deserializes() -> None:
    """cbor-raw: msg is {secs, nsecs, bytes} and the bytes deserialize back with rclpy."""
    from geometry_msgs.msg import PoseStamped

    msg = converter_for(PoseStamped).from_obj(
        {"header": {"frame_id": "map"}, "pose": {"position": {"x": 1.5}}}
    )
    data = encode_publish_cbor_raw("/pose", serialize(msg), 1_700_000_000_123_456_789)
    op = cbor2.loads(data)
    assert op["op"] == "publish" and op["topic"] == "/pose"
    assert op["msg"]["secs"] == 1_700_000_000
    assert op["msg"]["nsecs"] == 123_456_789
    assert deserialize(op["msg"]["bytes"], PoseStamped) == msg


def test_publish_json_envelope() -> None:
    """encode_publish_json wraps the shared msg text in a valid publish op, escaping the topic."""
    from std_msgs.msg import String

    conv = converter_for(String)
    text = encode_publish_json('/we"ird', conv.to_json(String(data="hi")))
    assert strict_loads(text) == {"op": "publish", "topic": '/we"ird', "msg": {"data": "hi"}}


def test_converter_is_cached_and_describes_the_type() -> None:
    """converter_for returns one converter per class, with its canonical name and field order."""
    from geometry_msgs.msg import Twist

    conv = converter_for(Twist)
    assert converter_for(Twist) is conv
    assert conv.type_name == "geometry_msgs/msg/Twist"
    assert conv.fields == ("linear", "angular")
    assert conv.msg_cls is Twist


def test_conversion_error_is_a_bridge_value_error() -> None:
    """ConversionError belongs to the bridge's error tree and is a ValueError."""
    from geometry_msgs.msg import Point

    err = error_of(converter_for(Point), {"x": "a"})
    assert isinstance(err, BridgeError) and isinstance(err, ValueError)


# --------------------------------------------------------------------------------------------
# sweep over every installed interface


def _index_dir() -> Path:
    return Path(sys.prefix) / "share" / "ament_index" / "resource_index" / "rosidl_interfaces"


def _all_classes() -> Iterator[tuple[str, type[Any]]]:
    """Every message class, every service's Request/Response/Event and every action's parts."""
    import importlib

    for entry in sorted(_index_dir().iterdir()):
        pkg = entry.name
        for line in entry.read_text().splitlines():
            kind, _, file = line.strip().partition("/")
            if not file.endswith(".idl"):
                continue
            name = file[: -len(".idl")]
            cls = getattr(importlib.import_module(f"{pkg}.{kind}"), name)
            if kind == "msg":
                yield f"{pkg}/msg/{name}", cls
            elif kind == "srv":
                for part in ("Request", "Response", "Event"):
                    if hasattr(cls, part):
                        yield f"{pkg}/srv/{name}_{part}", getattr(cls, part)
            elif kind == "action":
                impl = cls.Impl
                parts = {
                    "Goal": cls.Goal,
                    "Result": cls.Result,
                    "Feedback": cls.Feedback,
                    "SendGoal_Request": impl.SendGoalService.Request,
                    "SendGoal_Response": impl.SendGoalService.Response,
                    "GetResult_Request": impl.GetResultService.Request,
                    "GetResult_Response": impl.GetResultService.Response,
                    "FeedbackMessage": impl.FeedbackMessage,
                }
                for part, pcls in parts.items():
                    yield f"{pkg}/action/{name}_{part}", pcls


ALL_CLASSES = list(_all_classes())


def _sample(slot_type: Any, owner: type[Any]) -> Any:
    """A non-default value for one rosidl slot type (used to fill messages in the sweep)."""
    t = slot_type
    if isinstance(t, idl.AbstractNestedType):
        if isinstance(t, idl.Array):
            n = t.size
        elif isinstance(t, idl.BoundedSequence):
            n = min(t.maximum_size, 2)
        else:
            n = 2
        return [_sample(t.value_type, owner) for _ in range(n)]
    if isinstance(t, idl.BasicType):
        tn = t.typename
        if tn == "boolean":
            return True
        if tn == "octet":
            return b"\x07"
        if tn in ("float", "double"):
            return 1.5
        if tn in ("char", "wchar"):
            return "c"
        return {"int8": -7, "int16": -300, "int32": -70000, "int64": -(2**40)}.get(tn, 200)
    if isinstance(t, idl.AbstractGenericString):
        bound = getattr(t, "maximum_size", None)
        text = "sé\u2603" if isinstance(t, idl.AbstractWString) else "sé"
        return text[: bound if bound is not None else None]
    if isinstance(t, idl.NamespacedType):
        import importlib

        module = importlib.import_module(".".join(t.namespaces))
        # action parts (Fibonacci_Goal) live only in the owner's private module
        cls = getattr(module, t.name, None) or getattr(sys.modules[owner.__module__], t.name)
        return _filled(cls)
    raise AssertionError(f"unexpected slot type {t!r}")


def _filled(cls: type[Any]) -> Any:
    """An instance of cls with every field set to a non-default value."""
    msg = cls()
    for name, slot in zip(cls.get_fields_and_field_types(), cls.SLOT_TYPES, strict=True):
        setattr(msg, name, _sample(slot, cls))
    return msg


@pytest.mark.parametrize(("name", "cls"), ALL_CLASSES, ids=[n for n, _ in ALL_CLASSES])
def test_sweep_every_installed_type_round_trips(name: str, cls: type[Any]) -> None:
    """Default and filled instances survive JSON and CBOR both ways and stay rclpy-serializable."""
    conv = converter_for(cls)
    assert conv.type_name == name
    for msg in (cls(), _filled(cls)):
        back = via_json(conv, msg)
        assert back == msg
        assert strict_loads(conv.to_json(msg)) == strict_loads(json.dumps(conv.to_obj(msg)))
        assert via_cbor(conv, msg) == msg
        assert deserialize(serialize(back), cls) == msg
        # what a subscription hands the bridge: a message built by rclpy's C layer
        received = deserialize(serialize(msg), cls)
        assert conv.to_json(received) == conv.to_json(msg)
        assert cbor2.dumps(conv.to_cbor_obj(received)) == cbor2.dumps(conv.to_cbor_obj(msg))
    assert conv.from_obj({}) == cls()
    # each field given alone: every other field must come out at its default
    filled_obj = strict_loads(conv.to_json(_filled(cls)))
    for field in conv.fields:
        partial = conv.from_obj({field: filled_obj[field]})
        expected = cls()
        setattr(expected, field, getattr(_filled(cls), field))
        assert partial == expected, field
        assert deserialize(serialize(partial), cls) == expected


def test_sweep_covers_the_required_packages() -> None:
    """The sweep really includes every package the bridge promises to handle."""
    pkgs = {n.split("/")[0] for n, _ in ALL_CLASSES}
    required = {
        "std_msgs",
        "geometry_msgs",
        "sensor_msgs",
        "nav_msgs",
        "diagnostic_msgs",
        "shape_msgs",
        "stereo_msgs",
        "trajectory_msgs",
        "visualization_msgs",
        "actionlib_msgs",
        "builtin_interfaces",
        "std_srvs",
        "test_msgs",
        "action_msgs",
        "unique_identifier_msgs",
        "mult_msgs",
    }
    assert required <= pkgs, required - pkgs
    assert len(ALL_CLASSES) > 200


def test_cbor_envelope_matches_plain_encoding() -> None:
    """The cached CBOR envelope gives exactly the bytes of encoding the whole op dict."""
    from std_msgs.msg import String

    conv = converter_for(String)
    for topic in ("/a", "/b", "/a"):
        msg = String(data=f"on {topic}")
        expected = cbor2.dumps({"op": "publish", "topic": topic, "msg": {"data": f"on {topic}"}})
        assert encode_publish_cbor(topic, msg, conv) == expected


def test_tune_allocator_applies_on_glibc_linux() -> None:
    """tune_allocator reports success where glibc's mallopt exists (this Linux), else False."""
    import platform

    result = convert_mod.tune_allocator()
    assert isinstance(result, bool)
    if sys.platform.startswith("linux") and platform.libc_ver()[0] == "glibc":
        assert result is True


# --------------------------------------------------------------------------------------------
# fuzz: any JSON value gives a message rclpy can serialize, or a ConversionError


_json_scalars = (
    st.none()
    | st.booleans()
    | st.integers(min_value=-(2**70), max_value=2**70)
    | st.sampled_from([0, 1, 127, 128, 255, 256, -1, 2**31, 2**32, 2**63, 2**64, -(2**63) - 1])
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.sampled_from([3.0, 1e39, -1e39, 3.4028234663852886e38, 0.5])
    | st.text(max_size=30)
    | st.sampled_from(["AAAA", "AQID", "not base64!", "now", "é" * 12])
)
_json_values = st.recursive(
    _json_scalars,
    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=8), inner),
    max_leaves=20,
)

_FUZZ_TYPES = [
    "test_msgs/msg/BasicTypes",
    "test_msgs/msg/Arrays",
    "test_msgs/msg/BoundedSequences",
    "test_msgs/msg/UnboundedSequences",
    "test_msgs/msg/Strings",
    "geometry_msgs/msg/PoseStamped",
    "sensor_msgs/msg/Image",
    "nav_msgs/msg/Path",
]


_INT_LIMITS = {
    "int8": (-(2**7), 2**7 - 1),
    "uint8": (0, 2**8 - 1),
    "int16": (-(2**15), 2**15 - 1),
    "uint16": (0, 2**16 - 1),
    "int32": (-(2**31), 2**31 - 1),
    "uint32": (0, 2**32 - 1),
    "int64": (-(2**63), 2**63 - 1),
    "uint64": (0, 2**64 - 1),
}


def _near_valid(slot: Any, owner: type[Any], depth: int = 0) -> st.SearchStrategy[Any]:
    """Values that are mostly valid for a slot type, straying just past its limits."""
    import importlib

    if isinstance(slot, idl.AbstractNestedType):
        limit = getattr(slot, "size", None) or getattr(slot, "maximum_size", None) or 3
        items = st.lists(_near_valid(slot.value_type, owner, depth + 1), max_size=limit + 1)
        vt = slot.value_type
        if isinstance(vt, idl.BasicType) and vt.typename in ("uint8", "octet"):
            raw = st.binary(max_size=limit + 1)
            return items | raw.map(lambda b: base64.b64encode(b).decode()) | raw
        return items
    if isinstance(slot, idl.BasicType):
        tn = slot.typename
        if tn == "boolean":
            return st.booleans() | st.sampled_from([0, 1])
        if tn in ("float", "double"):
            return st.floats() | st.none() | st.integers(-(2**64), 2**64)
        lo, hi = _INT_LIMITS.get(tn, (0, 255))
        return st.integers(lo - 1, hi + 1) | st.sampled_from([lo, hi, float(lo), 0.5])
    if isinstance(slot, idl.AbstractGenericString):
        bound = getattr(slot, "maximum_size", None)
        return st.text(max_size=(bound + 2) if bound is not None else 12)
    if isinstance(slot, idl.NamespacedType):
        module = importlib.import_module(".".join(slot.namespaces))
        cls = getattr(module, slot.name, None) or getattr(sys.modules[owner.__module__], slot.name)
        if depth > 2:
            return st.just({})
        return _near_valid_object(cls, depth + 1)
    return _json_values


def _near_valid_object(cls: type[Any], depth: int = 0) -> st.SearchStrategy[dict[str, Any]]:
    """A JSON object whose keys are the type's fields, with mostly valid values."""
    fields = list(cls.get_fields_and_field_types())
    slots = dict(zip(fields, cls.SLOT_TYPES, strict=True))
    if not fields:
        return st.just({})
    return st.lists(st.sampled_from(fields), max_size=len(fields), unique=True).flatmap(
        lambda keys: st.fixed_dictionaries(
            {k: _near_valid(slots[k], cls, depth) for k in keys}
        )
    )


@st.composite
def _fuzz_cases(draw: st.DrawFn) -> tuple[type[Any], dict[str, Any]]:
    """A message type and a random JSON object for it: near-valid, or arbitrary JSON."""
    from bridge_server.rclpy_graph.types import resolve_message

    cls = resolve_message(draw(st.sampled_from(_FUZZ_TYPES)))
    keys = st.sampled_from(list(cls.get_fields_and_field_types())) | st.text(max_size=6)
    arbitrary = st.dictionaries(keys, _json_values, max_size=6)
    return cls, draw(_near_valid_object(cls) | arbitrary)


@settings(
    max_examples=250,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    database=None,
)
@given(_fuzz_cases())
def test_fuzz_from_obj_gives_serializable_message_or_conversion_error(
    case: tuple[type[Any], dict[str, Any]],
) -> None:
    """Random JSON for a message type: either a message rclpy serializes, or a ConversionError."""
    cls, obj = case
    conv = converter_for(cls)
    try:
        msg = conv.from_obj(obj)
    except ConversionError as exc:
        assert str(exc)
        return
    assert isinstance(msg, cls)
    assert deserialize(serialize(msg), cls) is not None
    strict_loads(conv.to_json(msg))
    cbor2.dumps(conv.to_cbor_obj(msg))


def test_from_obj_takes_keyword_arguments() -> None:
    """from_obj can be called with obj= and path= keywords, as its signature documents."""
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import Point

    assert converter_for(Point).from_obj(obj={"x": 2.0}, path="msg").x == 2.0
    assert converter_for(Time).from_obj(obj={"secs": 1}, path="t") == Time(sec=1)
    with pytest.raises(ConversionError) as info:
        converter_for(Time).from_obj(obj={"sec": "x"}, path="t")
    assert info.value.path == "t.sec"


def test_int8_arrays_text_matches_values() -> None:
    """int8 arrays (e.g. OccupancyGrid data) go out as the right JSON numbers at every value."""
    from nav_msgs.msg import OccupancyGrid
    from test_msgs.msg import Arrays

    conv = converter_for(OccupancyGrid)
    values = list(range(-128, 128))
    grid = conv.from_obj({"data": values})
    assert strict_loads(conv.to_json(grid))["data"] == values
    assert conv.to_obj(grid)["data"] == values
    fixed = converter_for(Arrays).from_obj({"int8_values": [-128, -1, 127]})
    assert strict_loads(converter_for(Arrays).to_json(fixed))["int8_values"] == [-128, -1, 127]
