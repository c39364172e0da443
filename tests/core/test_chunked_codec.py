"""The relay's piecewise encoders of large messages (rosbridge_core/codec/chunked.py) give,
byte for byte, what the one-call encoders give: JSON as cdr_json's (``bytes`` as base64),
CBOR as ``cbor2.dumps``, on decoded real messages and on nested shapes."""

from __future__ import annotations

import math
from typing import Any

import cbor2
import pytest

from msgs import cdr
from msgs.runtime import lookup_message
from rosbridge_core.codec import cdr_json
from rosbridge_core.codec.chunked import PIECE, cbor_bytes, json_text


def _decoded(type_name: str, values: dict[str, Any], typed: bool) -> Any:
    cls = lookup_message(type_name)
    data = cdr.encode(cls.from_json(values))
    return cdr.decoder_for(cls, cbor2.CBORTag if typed else None)(data), cls, data


SHAPES = [
    ("geometry_msgs/msg/PoseArray", {"header": {"frame_id": "map"},
                                     "poses": [{"position": {"x": i / 3}} for i in range(3000)]}),
    ("sensor_msgs/msg/PointCloud2", {"fields": [{"name": "x", "datatype": 7, "count": 1}] * 3,
                                     "data": bytes(range(256)) * 64}),
    ("sensor_msgs/msg/JointState", {"name": [f"j{i}é\"" for i in range(2 * PIECE + 1)],
                                    "position": [i / 7 for i in range(2 * PIECE + 1)]}),
    ("visualization_msgs/msg/MarkerArray", {"markers": [
        {"points": [{"x": 1.5}] * (PIECE + 3), "text": "a\nb"} for _ in range(3)]}),
]


@pytest.mark.parametrize(("type_name", "values"), SHAPES, ids=[s[0] for s in SHAPES])
def test_pieces_make_the_same_text_and_bytes(type_name: str, values: dict[str, Any]) -> None:
    """JSON in pieces is cdr_json's text of the same CDR bytes; CBOR in pieces is
    cbor2.dumps of the typed decode."""
    plain, cls, data = _decoded(type_name, values, typed=False)
    assert json_text(plain) == cdr_json.msgs_encoder(cls)(data)
    typed, _, _ = _decoded(type_name, values, typed=True)
    assert cbor_bytes(typed, cbor2.dumps) == cbor2.dumps(typed)


def test_nested_lists_and_a_nan() -> None:
    """Lists of lists over PIECE items, empty ones, bytes in lists: the same; a NaN is a
    ValueError, as for the one-call encoder."""
    value = {"a": [[1] * (PIECE + 1)] * 3, "b": [], "c": [b"xy"] * (PIECE + 2), "d": {"e": {}}}
    assert json_text(value) == cdr_json._encode(value)
    assert cbor_bytes(value, cbor2.dumps) == cbor2.dumps(value)
    with pytest.raises(ValueError):
        json_text({"x": [1.0] * PIECE + [math.nan]})
