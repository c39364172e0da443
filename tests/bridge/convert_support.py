"""Helpers shared by the conversion tests (tests/bridge/test_convert_*.py).

JSON and CBOR round trips, typed-array untagging, and the numeric array samples.
"""

from __future__ import annotations

import array
import json
import sys
import warnings
from typing import Any

import cbor2
import pytest

from bridge_server.rclpy_graph.convert import (
    ConversionError,
    Converter,
    encode_publish_cbor,
)

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


# numeric array fields: (element type, valid values, one invalid value)
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
