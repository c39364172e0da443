"""msgs.cdr against rclpy's own serializer: every type msgs generates decodes to what the
bridge's JSON gives, random values round-trip, and malformed CDR fails naming the field."""

from __future__ import annotations

import json
import re
import struct
from collections.abc import Callable
from typing import Any, Literal

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rclpy.serialization import deserialize_message, serialize_message

from bridge_server.rclpy_graph import convert
from bridge_server.rclpy_graph.types import resolve_action, resolve_message, resolve_service
from msgs import cdr
from msgs.runtime import Message, Service, available_types, lookup, lookup_message
from msgs.sensor_msgs.msg import Image, Imu, PointCloud2
from msgs.test_msgs.msg import Arrays, BoundedSequences, UnboundedSequences, WStrings

_SURROGATES: tuple[Literal["Cs"]] = ("Cs",)
"""Surrogates are not text a message can carry."""


def _message_types() -> list[type[Message]]:
    """Every message type msgs generates, service and action parts included."""
    found: list[type[Message]] = []
    for name in available_types():
        cls = lookup(name)
        if issubclass(cls, Message):
            found.append(cls)
        else:
            parts = ("Request", "Response") if issubclass(cls, Service) else (
                "Goal", "Result", "Feedback")
            found += [getattr(cls, part) for part in parts]
    return found


def _rclpy_class(type_name: str) -> type[Any]:
    """rclpy's class of a message type, service and action parts included."""
    pkg, kind, name = type_name.split("/")
    if kind == "msg":
        return resolve_message(type_name)
    base, part = name.rsplit("_", 1)
    owner = (resolve_service if kind == "srv" else resolve_action)(f"{pkg}/{kind}/{base}")
    cls: type[Any] = getattr(owner, part)
    return cls


def _rclpy(msg: Message) -> Any:
    """The same message as an rclpy instance (through the bridge's converter)."""
    rcls = _rclpy_class(msg._type)
    return convert.converter_for(rcls).from_obj(json.loads(json.dumps(msg.to_json())), "msg")


@pytest.mark.parametrize("cls", _message_types(), ids=lambda c: c._type)
def test_every_type_decodes_as_the_bridge_converts_it(cls: type[Message]) -> None:
    """A default message of each type: CDR decoded here equals the bridge's JSON of it."""
    rcls = _rclpy_class(cls._type)
    ros_msg = rcls()
    ours = cdr.decode(serialize_message(ros_msg), cls)
    want = json.loads(convert.converter_for(rcls).to_json(ros_msg))
    assert cls.from_json(ours) == cls.from_json(want)


_BOUND = re.compile(r"<(\d+)>")
_INTS = {"octet": (0, 255), "uint8": (0, 255), "char": (0, 255), "int8": (-128, 127),
         "int16": (-(2**15), 2**15 - 1), "uint16": (0, 2**16 - 1),
         "int32": (-(2**31), 2**31 - 1), "uint32": (0, 2**32 - 1),
         "int64": (-(2**63), 2**63 - 1), "uint64": (0, 2**64 - 1)}


def _scalar(base: str) -> st.SearchStrategy[Any]:
    if base in _INTS:
        return st.integers(*_INTS[base])
    if base == "boolean":
        return st.booleans()
    if base == "float":
        return st.floats(width=32, allow_nan=False, allow_infinity=False)
    if base == "double":
        return st.floats(allow_nan=False, allow_infinity=False)
    if base.startswith(("string", "wstring")):
        bound = _BOUND.search(base)
        chars = st.characters(blacklist_categories=_SURROGATES, blacklist_characters="\x00")
        return st.text(chars, max_size=int(bound[1]) if bound else 6)
    return _message(lookup_message(base)).map(lambda m: m.to_json())


def _field(spec: str) -> st.SearchStrategy[Any]:
    seq = re.match(r"^sequence<([^,<>]+(?:<\d+>)?)(?:, *(\d+))?>$", spec)
    fixed = re.match(r"^(.+)\[(\d+)\]$", spec)
    if seq:
        most = min(int(seq[2]), 3) if seq[2] else 3
        base, size = seq[1], st.lists(_scalar(seq[1]), max_size=most)
    elif fixed:
        n = int(fixed[2])
        base, size = fixed[1], st.lists(_scalar(fixed[1]), min_size=n, max_size=n)
    else:
        return _scalar(spec)
    if base in ("uint8", "char"):
        return size.map(bytes)
    return size


def _message(cls: type[Message]) -> st.SearchStrategy[Message]:
    fields = {name: _field(spec) for name, spec in cls._fields_and_types.items()}
    return st.fixed_dictionaries(fields).map(cls.from_json)


def over_rich_types(test: Callable[[type[Message], st.DataObject], None]) -> Any:
    """Run ``test(cls, data)`` for types with every kind of field, drawing random messages."""
    rich = [Arrays, BoundedSequences, UnboundedSequences, WStrings, Imu, Image, PointCloud2]
    test = given(data=st.data())(test)
    test = settings(max_examples=25, deadline=None, suppress_health_check=[
        HealthCheck.too_slow, HealthCheck.data_too_large])(test)
    return pytest.mark.parametrize("cls", rich, ids=lambda c: c._type)(test)


@over_rich_types
def test_random_messages_round_trip_through_rclpy(cls: type[Message], data: st.DataObject) -> None:
    """Random values: serialized by rclpy, decoded here, the same message comes back; and
    serialized here, rclpy reads the same message."""
    msg = data.draw(_message(cls))
    _assert_same_bytes(msg)
    assert cls.from_json(cdr.decode(cdr.encode(msg), cls)) == msg
    decoded = cls.from_json(cdr.decode(serialize_message(_rclpy(msg)), cls))
    assert decoded == msg


def test_truncated_and_malformed_cdr_fail_naming_the_field() -> None:
    """Every cut of a serialized Image fails with CdrError (never a wrong message); the error
    names the type and the field; a bad header and an impossible length are refused too."""
    image = Image.from_json({"header": {"frame_id": "cam"}, "encoding": "rgb8", "width": 2,
                             "height": 1, "step": 6, "data": b"abcdef"})
    data = serialize_message(_rclpy(image))
    for cut in range(len(data)):
        with pytest.raises(cdr.CdrError) as info:
            cdr.decode(data[:cut], Image)
        assert str(info.value).startswith("sensor_msgs/msg/Image: cannot decode")
    with pytest.raises(cdr.CdrError, match="'data'"):
        cdr.decode(data[:-1], Image)
    with pytest.raises(cdr.CdrError, match="little-endian"):
        cdr.decode(b"\x00\x00\x00\x00" + data[4:], Image)
    huge = bytearray(data)
    at = data.index(b"cam") - 4  # the frame_id's length
    huge[at:at + 4] = struct.pack("<I", 2**31)
    with pytest.raises(cdr.CdrError, match=r"'header\.frame_id'"):
        cdr.decode(bytes(huge), Image)


@pytest.mark.parametrize("cls", _message_types(), ids=lambda c: c._type)
def test_every_type_encodes_as_rclpy_serializes_it(cls: type[Message]) -> None:
    """A default message of each type: rclpy reads msgs.cdr.encode's bytes back as the
    message, and our decoder reads rclpy's bytes and ours alike. (rclpy's own bytes are not
    compared: its padding and the tail of its buffer hold undefined bytes.)"""
    msg = cls()
    _assert_same_bytes(msg)


def _assert_same_bytes(msg: Message) -> None:
    ours = cdr.encode(msg)
    expected = _rclpy(msg)
    assert deserialize_message(ours, type(expected)) == expected
    cls = type(msg)
    theirs = serialize_message(expected)
    assert cdr.decode(ours, cls) == cdr.decode(theirs, cls)


def test_a_value_that_does_not_fit_fails_naming_the_field() -> None:
    """encode names the field whose value cannot be serialized (here out of int32 range)."""
    bad = Imu()
    bad.header.stamp.sec = 2**40
    with pytest.raises(cdr.CdrError, match=r"Imu: cannot encode field .header\.stamp\.sec. to CDR: .*"):
        cdr.encode(bad)
