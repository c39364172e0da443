"""JSON straight from CDR (rosbridge_core.codec.cdr_json) gives the converter's text exactly, for
every type msgs generates, and leaves what it cannot render the same way to the converter."""

from __future__ import annotations

import math
import sys
import types
from typing import Any

import pytest
from hypothesis import strategies as st
from rclpy.serialization import serialize_message

from bridge_server.rclpy_graph import convert
from bridge_server.rclpy_graph.node import Incoming
from msgs.runtime import Message
from rosbridge_core.codec import cdr_json
from tests.msgs.test_cdr import (
    _message,
    _message_types,
    _rclpy,
    _rclpy_class,
    over_rich_types,
)


@pytest.mark.parametrize("cls", _message_types(), ids=lambda c: c._type)
def test_every_type_gives_the_converters_text(cls: type[Message]) -> None:
    rcls = _rclpy_class(cls._type)
    conv = convert.converter_for(rcls)
    assert conv.json_from_cdr is not None, "msgs and the installed type differ in layout"
    ros_msg = rcls()
    assert conv.json_from_cdr(serialize_message(ros_msg)) == conv.to_json(ros_msg)


@over_rich_types
def test_random_messages_give_the_converters_text(cls: type[Message], data: st.DataObject) -> None:
    ros_msg = _rclpy(data.draw(_message(cls)))
    conv = convert.converter_for(type(ros_msg))
    assert conv.json_from_cdr is not None
    assert conv.json_from_cdr(serialize_message(ros_msg)) == conv.to_json(ros_msg)


def test_nan_and_bad_bytes_are_left_to_the_converter() -> None:
    from sensor_msgs.msg import Imu as RosImu

    conv = convert.converter_for(RosImu)
    assert conv.json_from_cdr is not None
    msg = RosImu()
    msg.orientation.x = math.nan
    msg.linear_acceleration_covariance[3] = math.inf
    data = serialize_message(msg)
    assert conv.json_from_cdr(data) is None
    # the Incoming a subscriber gets has the converter's text: null for NaN and Inf
    text = Incoming("/imu", data, conv, 0).json_text()
    assert '"orientation":{"x":null,' in text
    assert "NaN" not in text and "Infinity" not in text
    assert conv.json_from_cdr(data[:20]) is None  # truncated


def _fake_rclpy_class(fields: dict[str, str]) -> type[Any]:
    return type("Fake", (), {"get_fields_and_field_types": staticmethod(lambda: fields),
                             "SLOT_TYPES": ()})


def test_a_type_with_another_layout_or_unknown_to_msgs_has_no_fast_path() -> None:
    # the robot's std_msgs/String from another release, say, with another field
    other = _fake_rclpy_class({"data": "string", "extra": "int32"})
    assert cdr_json.encoder_for(other, "std_msgs/msg/String") is None
    same = _fake_rclpy_class({"data": "string"})
    assert cdr_json.encoder_for(same, "std_msgs/msg/String") is not None
    assert cdr_json.encoder_for(same, "robot_only_msgs/msg/Thing") is None


def test_a_nested_type_with_another_layout_has_no_fast_path(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from rosidl_parser.definition import NamespacedType

    fields = {"stamp": "builtin_interfaces/Time", "frame_id": "string"}
    header = type("Header", (), {
        "get_fields_and_field_types": staticmethod(lambda: fields),
        "SLOT_TYPES": (NamespacedType(["builtin_interfaces", "msg"], "Time"),),
    })
    assert cdr_json.encoder_for(header, "std_msgs/msg/Header") is not None
    # the same Header on a robot whose builtin_interfaces/Time has another layout
    module = types.ModuleType("builtin_interfaces.msg")
    module.Time = _fake_rclpy_class({"sec": "int64", "nanosec": "uint32"})  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "builtin_interfaces.msg", module)
    assert cdr_json.encoder_for(header, "std_msgs/msg/Header") is None


@pytest.mark.parametrize(("type_name", "item"), [
    ("sensor_msgs/msg/PointCloud2", "PointField"),  # sequence<sensor_msgs/PointField>
    ("test_msgs/msg/Arrays", "BasicTypes"),  # test_msgs/BasicTypes[3]
])
def test_an_item_type_of_a_sequence_or_array_with_another_layout_has_no_fast_path(
    monkeypatch: pytest.MonkeyPatch, type_name: str, item: str,
) -> None:
    """Items of sequences and fixed arrays of messages are compared too: the installed
    PointCloud2 (or Arrays) on a robot whose PointField (BasicTypes) differs gets no fast
    encoder, which would read its items with msgs' layout."""
    rclpy_cls = _rclpy_class(type_name)
    assert cdr_json.encoder_for(rclpy_cls, type_name) is not None
    package = type_name.split("/msg/")[0] + ".msg"
    real = sys.modules[package]
    module = types.ModuleType(package)
    module.__getattr__ = lambda name: getattr(real, name)  # type: ignore[method-assign]
    setattr(module, item, _fake_rclpy_class({
        **_rclpy_class(f"{package.replace('.', '/')}/{item}").get_fields_and_field_types(),
        "extra": "uint8"}))
    monkeypatch.setitem(sys.modules, package, module)
    assert cdr_json.encoder_for(rclpy_cls, type_name) is None


@pytest.mark.parametrize("size", [0, 1, 2, 3, 57, 4096, 640 * 480 * 3])
def test_b64_text_is_standard_base64(size: int) -> None:
    """The SIMD base64 gives the standard library's text for bytes, arrays and views."""
    import array
    import binascii
    import os

    raw = os.urandom(size)
    want = binascii.b2a_base64(raw, newline=False).decode("ascii")
    for value in (raw, array.array("B", raw), memoryview(raw), bytearray(raw)):
        text = cdr_json.b64_text(value)
        assert type(text) is str and text == want
    assert cdr_json._b64_text_stdlib(raw) == want


def _camera_frame() -> Any:
    import os

    from sensor_msgs.msg import Image as RosImage

    msg = RosImage()
    msg.header.frame_id = 'cam "front"'
    msg.header.stamp.sec, msg.header.stamp.nanosec = 17, 25
    msg.height, msg.width, msg.encoding, msg.step = 480, 640, "rgb8", 1920
    msg.data = os.urandom(480 * 1920)
    return msg


def test_byte_arrays_anywhere_among_the_fields_give_the_converters_text() -> None:
    """Byte arrays first, between other fields and last (fixed, bounded, unbounded, char)
    are placed as base64 between the encoder's text of the fields around them."""
    import os

    from test_msgs.msg import Arrays, BoundedSequences, UnboundedSequences

    for msg in (_camera_frame(), Arrays(), BoundedSequences(), UnboundedSequences()):
        for name in msg.get_fields_and_field_types():
            if name in ("uint8_values", "char_values", "byte_values"):
                size = len(getattr(msg, name)) or 3
                if name == "byte_values":
                    setattr(msg, name, [bytes([b]) for b in os.urandom(size)])
                else:
                    setattr(msg, name, [b % (256 if name == "uint8_values" else 128)
                                        for b in os.urandom(size)])
        conv = convert.converter_for(type(msg))
        assert conv.json_from_cdr is not None
        text = conv.json_from_cdr(serialize_message(msg))
        assert text == conv.to_json(msg)
        # and it is JSON whose byte arrays decode back to the message's bytes
        import base64
        import json

        obj = json.loads(text)
        if "uint8_values" in obj:
            assert base64.b64decode(obj["uint8_values"]) == bytes(msg.uint8_values)
        if "data" in obj:
            assert base64.b64decode(obj["data"]) == bytes(msg.data)


_FLOATS = {"float", "double"}


def _fill_floats(msg: Any, value: float) -> int:
    """Set every float of an rclpy message (nested, in fixed arrays, one item in each float
    sequence) to ``value``; how many were set."""
    from rosidl_parser.definition import AbstractNestedType, Array, BasicType, NamespacedType

    n = 0
    for name, kind in zip(msg.get_fields_and_field_types(), msg.SLOT_TYPES, strict=True):
        if isinstance(kind, BasicType) and kind.typename in _FLOATS:
            setattr(msg, name, value)
            n += 1
        elif isinstance(kind, NamespacedType):
            n += _fill_floats(getattr(msg, name), value)
        elif isinstance(kind, AbstractNestedType):
            item = kind.value_type
            if isinstance(item, BasicType) and item.typename in _FLOATS:
                if isinstance(kind, Array):
                    getattr(msg, name)[:] = value
                    n += kind.size
                else:
                    setattr(msg, name, [value])
                    n += 1
            elif isinstance(item, NamespacedType) and isinstance(kind, Array):
                n += sum(_fill_floats(m, value) for m in getattr(msg, name))
    return n


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf], ids=str)
def test_nan_and_inf_in_every_float_bearing_type_give_the_converters_text(value: float) -> None:
    """In every type msgs generates that carries a float (scalar, array, sequence, nested),
    every float set to NaN/Inf: the fast path declines, and the Incoming's text is the
    converter's (null for each, never NaN or Infinity in the JSON)."""
    from rclpy.serialization import deserialize_message

    tried = 0
    for cls in _message_types():
        rcls = _rclpy_class(cls._type)
        msg = rcls()
        count = _fill_floats(msg, value)
        if not count:
            continue
        tried += 1
        conv = convert.converter_for(rcls)
        data = serialize_message(msg)
        assert conv.json_from_cdr is not None and conv.json_from_cdr(data) is None, cls._type
        text = Incoming("/t", data, conv, 0).json_text()
        want = conv.to_json(deserialize_message(data, rcls))
        assert text == convert.encode_publish_json("/t", want), cls._type
        assert "NaN" not in text and "Infinity" not in text, cls._type
        assert text.count("null") >= min(count, 1), cls._type
    assert tried >= 20, tried  # geometry, sensor and nav types among them


class _CountingIncoming(Incoming):
    """An Incoming that counts how often its message is deserialized with rclpy."""

    __slots__ = ("deserialized",)

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.deserialized = 0

    @property
    def msg(self) -> Any:
        self.deserialized += 1
        return super().msg


def test_incoming_takes_the_cdr_fast_path_when_it_can() -> None:
    """A finite Imu's JSON comes straight from its CDR bytes: rclpy never deserializes it
    (for the JSON text, once for all subscribers); with a NaN in it, it falls back to one
    deserialization."""
    from sensor_msgs.msg import Imu as RosImu

    conv = convert.converter_for(RosImu)
    msg = RosImu()
    msg.linear_acceleration.z = 9.81
    fine = _CountingIncoming("/imu", serialize_message(msg), conv, 0)
    text = fine.json_text()
    assert fine.json_text("imu") and fine.json_text() is text
    assert fine.deserialized == 0 and '"z":9.81' in text
    msg.orientation.w = math.nan
    odd = _CountingIncoming("/imu", serialize_message(msg), conv, 0)
    odd.json_text()
    odd.json_text("imu")
    assert odd.deserialized == 1
