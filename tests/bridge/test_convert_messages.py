"""Conversion of whole messages, ROS message <-> rosbridge JSON/CBOR, with real rclpy classes.

bridge_server.rclpy_graph.convert: nested messages and error paths, defaults, Time/Duration,
the CBOR encodings and the publish envelopes.
"""

from __future__ import annotations

import math
import struct
import types
from typing import Any

import cbor2
import pytest

import bridge_server.rclpy_graph.convert as convert_mod
from bridge_server.rclpy_graph.convert import (
    ConversionError,
    converter_for,
    deserialize,
    encode_publish_cbor,
    encode_publish_cbor_raw,
    encode_publish_json,
    serialize,
)
from bridge_server.rclpy_graph.types import BridgeError
from tests.bridge.convert_support import (
    NUMERIC,
    error_of,
    strict_loads,
)

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


def test_from_obj_takes_keyword_arguments() -> None:
    """from_obj can be called with obj= and path= keywords, as its signature documents."""
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import Point

    assert converter_for(Point).from_obj(obj={"x": 2.0}, path="msg").x == 2.0
    assert converter_for(Time).from_obj(obj={"secs": 1}, path="t") == Time(sec=1)
    with pytest.raises(ConversionError) as info:
        converter_for(Time).from_obj(obj={"sec": "x"}, path="t")
    assert info.value.path == "t.sec"
