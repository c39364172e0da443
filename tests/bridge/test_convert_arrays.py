"""Conversion of arrays, ROS message <-> rosbridge JSON/CBOR, with real rclpy classes.

bridge_server.rclpy_graph.convert: numeric, bool and string arrays, uint8[]/char[] as base64,
byte[], and a 640x480 image.
"""

from __future__ import annotations

import array
import base64

import cbor2
import numpy
import pytest

from bridge_server.rclpy_graph.convert import (
    converter_for,
    deserialize,
    encode_publish_json,
    serialize,
)
from tests.bridge.convert_support import (
    NUMERIC,
    error_of,
    strict_loads,
    via_cbor,
    via_json,
)

# --------------------------------------------------------------------------------------------
# arrays


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
