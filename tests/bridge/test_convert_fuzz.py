"""Fuzz: any JSON value gives a message rclpy can serialize, or a ConversionError.

bridge_server.rclpy_graph.convert.Converter.from_obj fed near-valid objects by hypothesis.
"""

from __future__ import annotations

import base64
import sys
from typing import Any

import cbor2
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rosidl_parser import definition as idl

from bridge_server.rclpy_graph.convert import (
    ConversionError,
    converter_for,
    deserialize,
    serialize,
)
from tests.bridge.convert_support import (
    strict_loads,
)

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
