"""How msgs.cdr's generated decoders read arrays, at the edges mutation testing found
unchecked (issue 54): the form of each kind of array (octets, booleans, numbers; plain and
typed for CBOR), a 2-byte array's alignment, and a field of no IDL type refused when the
decoder is made, naming the field."""

from __future__ import annotations

import struct
from typing import Any

import cbor2
import pytest

from msgs import cdr
from msgs.runtime import lookup_message
from tests.msgs.test_cdr_bounds import _struct

HEADER = b"\x00\x01\x00\x00"


def _arrays() -> tuple[Any, bytes]:
    """A type of an octet, a boolean and an int32 sequence, and a message of two each."""
    cls = lookup_message(_struct(["byte[]", "bool[]", "int32[]"]))
    data = (HEADER + struct.pack("<I", 2) + bytes([200, 7]) + bytes(2)
            + struct.pack("<I", 2) + bytes([1, 0]) + bytes(2)
            + struct.pack("<I", 2) + struct.pack("<2i", -5, 9))
    return cls, data


def test_octets_are_ints_booleans_are_bools_when_plain() -> None:
    """Plain: an octet sequence is a list of ints, a boolean one a list of bools (not 1 and
    0), an int32 one a list of ints."""
    cls, data = _arrays()
    out = cdr.decode(data, cls)
    assert out == {"f0": [200, 7], "f1": [True, False], "f2": [-5, 9]}
    assert [type(v) for v in out["f0"] + out["f1"]] == [int, int, bool, bool]


def test_typed_octets_are_bytes_and_numbers_a_typed_array() -> None:
    """For CBOR (typed): an octet sequence is bytes, a boolean one still a list of bools,
    an int32 one a typed array of its little-endian bytes."""
    cls, data = _arrays()
    out = cdr.decoder_for(cls, typed=cbor2.CBORTag)(data)
    assert out["f0"] == bytes([200, 7])
    assert out["f1"] == [True, False] and all(type(v) is bool for v in out["f1"])
    assert out["f2"] == cbor2.CBORTag(cdr.TYPED_ARRAY_TAGS["int32"], struct.pack("<2i", -5, 9))


def test_a_two_byte_array_after_an_odd_offset_is_aligned() -> None:
    """A fixed int16 array after a uint8 starts at the next even offset, as rclpy writes it
    (the round trip through encode gives the values back)."""
    cls: Any = lookup_message(_struct(["uint8", "int16[2]"]))
    msg = cls(f0=3, f1=[-2, 300])
    data = cdr.encode(msg)
    assert data == HEADER + bytes([3, 0]) + struct.pack("<2h", -2, 300)
    assert cdr.decode(data, cls) == {"f0": 3, "f1": [-2, 300]}


def test_a_field_of_no_idl_type_is_refused_naming_it() -> None:
    """A type whose field's type is no IDL type cannot have a decoder: the error names the
    field and quotes the type."""
    class Bad:
        _type = "bad/msg/T"
        _fields_and_types = {"ok": "int32", "x": "int32["}
        _lookup = staticmethod(lookup_message)

    with pytest.raises(cdr.CdrError) as info:
        cdr.decoder_for(Bad)  # type: ignore[arg-type]
    assert (info.value.type_name, info.value.path, info.value.why) == (
        "?", "x", "unknown field type 'int32['")
