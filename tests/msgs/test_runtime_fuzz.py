"""Property tests: any decoded JSON/CBOR value gives a message or a ValidationError."""

from __future__ import annotations

import json
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from msgs.geometry_msgs.msg import PoseStamped
from msgs.runtime import Message, ValidationError
from msgs.sensor_msgs.msg import Image
from msgs.test_msgs.msg import Arrays, BoundedSequences, MultiNested

CLASSES: list[type[Message]] = [
    Arrays,
    BoundedSequences,
    Image,
    MultiNested,
    PoseStamped,
]
FIELD_NAMES = sorted(
    {name for cls in CLASSES for name in cls._fields_and_types}
    | {"x", "y", "z", "w", "sec", "nanosec", "frame_id", "int8_value", "bool_value", "data"}
)

_scalars = (
    st.none()
    | st.booleans()
    | st.integers(min_value=-(2**70), max_value=2**70)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=8)
    | st.binary(max_size=8)
)
_values = st.recursive(
    _scalars,
    lambda children: (
        st.lists(children, max_size=5)
        | st.dictionaries(st.sampled_from(FIELD_NAMES) | st.text(max_size=4), children, max_size=5)
    ),
    max_leaves=20,
)


@pytest.mark.parametrize("cls", CLASSES, ids=lambda c: c._type)
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(draw=st.data())
def test_from_json_gives_message_or_validation_error(
    cls: type[Message], draw: st.DataObject
) -> None:
    """Arbitrary input never raises anything but ValidationError; results validate and round-trip."""
    own_fields = st.sampled_from(sorted(cls._fields_and_types))
    data: Any = draw.draw(st.dictionaries(own_fields, _values, max_size=6))
    try:
        msg = cls.from_json(data)
    except ValidationError as exc:
        assert exc.path and str(exc).startswith(exc.path)
        return
    msg.validate()
    out = msg.to_json()
    text = json.dumps(out, allow_nan=False)
    assert cls.from_json(json.loads(text)).to_json() == out


@settings(max_examples=40, deadline=None)
@given(
    x=st.floats(allow_nan=True) | st.none() | st.integers(-(10**6), 10**6),
    frame=st.text(max_size=8),
    sec=st.integers(-(2**31), 2**31 - 1),
)
def test_valid_inputs_always_decode(x: Any, frame: str, sec: int) -> None:
    """Well-typed input of any value always decodes and round-trips through JSON."""
    data = {"header": {"stamp": {"sec": sec}, "frame_id": frame}, "pose": {"position": {"x": x}}}
    msg = PoseStamped.from_json(data)
    assert msg.header.stamp.sec == sec and msg.header.frame_id == frame
    out = msg.to_json()
    assert PoseStamped.from_json(json.loads(json.dumps(out, allow_nan=False))).to_json() == out
