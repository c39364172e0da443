"""Frames to ops without I/O: JSON and CBOR frames, typed arrays, fragments both ways."""

from __future__ import annotations

import array
import json
from typing import Any

import cbor2
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rosbridge_core.protocol.frames import (
    PIECE_COST,
    Conversation,
    decode_frame,
    decode_typed_array,
    split_fragments,
)
from rosbridge_core.protocol.ops import Fragment, Publish, encode, parse_op
from roslibpy_lite.exceptions import RemoteProtocolError


def test_text_frame_gives_an_op() -> None:
    """A JSON text frame becomes the op it holds."""
    assert Conversation().receive('{"op":"publish","topic":"/a","msg":{}}') == Publish("/a", {})


def test_malformed_json_says_where() -> None:
    """Malformed JSON is reported with line and column."""
    with pytest.raises(RemoteProtocolError, match="malformed JSON at line 1 column 2"):
        Conversation().receive("{oops")


def test_cbor_frame_with_typed_arrays_and_bytes() -> None:
    """A CBOR frame decodes RFC 8746 little-endian typed arrays to lists; byte strings stay bytes."""
    msg = {
        "f64": cbor2.CBORTag(86, array.array("d", [1.5, -2.0]).tobytes()),
        "f32": cbor2.CBORTag(85, array.array("f", [0.5]).tobytes()),
        "i16": cbor2.CBORTag(77, array.array("h", [-3, 4]).tobytes()),
        "u32": cbor2.CBORTag(70, array.array("I", [7]).tobytes()),
        "data": b"\x00\x01\xff",
    }
    frame = cbor2.dumps({"op": "publish", "topic": "/img", "msg": msg})
    op = Conversation().receive(frame)
    assert op == Publish("/img", {"f64": [1.5, -2.0], "f32": [0.5], "i16": [-3, 4],
                                  "u32": [7], "data": b"\x00\x01\xff"})


def test_big_endian_typed_arrays_are_swapped() -> None:
    """Big-endian typed-array tags are decoded too."""
    assert decode_typed_array(66, (1).to_bytes(4, "big") + (2).to_bytes(4, "big")) == [1, 2]


def test_typed_array_with_ragged_length_is_an_error() -> None:
    """A typed array whose byte length is not a multiple of its element size is refused."""
    with pytest.raises(RemoteProtocolError, match="not a multiple of 8"):
        decode_typed_array(86, b"123")


def test_malformed_cbor_is_an_error() -> None:
    """A binary frame that is not CBOR is reported as such."""
    with pytest.raises(RemoteProtocolError, match="malformed CBOR"):
        decode_frame(b"\xff\xff\xff")


def test_fragments_reassemble_in_any_order() -> None:
    """Fragments of one op, out of order, reassemble into that op; the earlier ones give None."""
    op = Publish("/a", {"data": "x" * 100})
    text = encode(op)
    pieces = split_fragments(text, 30, "big-1")
    assert len(pieces) == -(-len(text) // 30) > 1
    proto = Conversation()
    results = [proto.receive(p) for p in reversed(pieces)]
    assert all(r is None for r in results[:-1]) and results[-1] == op
    assert proto.pending_fragments == 0


def test_small_text_is_not_fragmented() -> None:
    """A text within the fragment size is sent as it is."""
    assert split_fragments('{"op":"status"}', 100, 1) == ['{"op":"status"}']


def test_fragment_total_must_not_change() -> None:
    """A fragment whose total disagrees with earlier pieces of the same id is refused."""
    proto = Conversation()
    proto.receive_fragment(Fragment("f", "{", 0, 3))
    with pytest.raises(RemoteProtocolError, match="total changed from 3 to 2"):
        proto.receive_fragment(Fragment("f", "}", 1, 2))


def test_reassembled_garbage_names_the_fragment_id() -> None:
    """Pieces that join into invalid JSON fail with the fragment id."""
    proto = Conversation()
    proto.receive_fragment(Fragment("f9", "{not", 0, 2))
    with pytest.raises(RemoteProtocolError, match="fragment 'f9': reassembled op is invalid") as info:
        proto.receive_fragment(Fragment("f9", " json", 1, 2))
    assert info.value.id == "f9"


def test_partial_fragments_are_bounded() -> None:
    """At most max_partial incomplete ops wait; the oldest is dropped beyond that."""
    proto = Conversation(max_partial=2)
    for i in range(5):
        proto.receive_fragment(Fragment(f"f{i}", "x", 0, 2))
    assert proto.pending_fragments == 2


def test_reassembled_size_is_bounded() -> None:
    """A fragmented op may not grow past max_fragment_bytes."""
    proto = Conversation(max_fragment_bytes=10)
    with pytest.raises(RemoteProtocolError, match="past 10 bytes"):
        proto.receive_fragment(Fragment("f", "x" * 11, 0, 2))
    assert proto.pending_fragments == 0 and proto.held_fragment_bytes == 0


def test_a_piece_sent_twice_is_refused_naming_the_id_and_the_piece() -> None:
    """A repeated piece number is an error naming the fragment id and the number; the op's
    pieces are dropped, so nothing sent again is held without being counted."""
    proto = Conversation(max_fragment_bytes=10_000)
    proto.receive_fragment(Fragment("f", "x", 0, 3))
    with pytest.raises(RemoteProtocolError, match="fragment 'f': piece 0 of 3 was sent twice") \
            as info:
        proto.receive_fragment(Fragment("f", "y" * 5000, 0, 3))
    assert info.value.id == "f" and info.value.op == "fragment"
    assert proto.pending_fragments == 0 and proto.held_fragment_bytes == 0


def test_every_piece_held_counts_whatever_the_ids_and_numbers() -> None:
    """The bound covers all incomplete ops together, each piece counted (tiny ones at least
    PIECE_COST): pieces sent small then again large, under many ids, never hold more."""
    limit = 64 * 1024
    proto = Conversation(max_partial=16, max_fragment_bytes=limit)
    refused = 0
    for i in range(200):
        for data in ("x", "y" * 4000):  # the attack of issue 39: small, then the same num big
            try:
                proto.receive_fragment(Fragment(f"f{i % 4}", data, i, 1000))
            except RemoteProtocolError:
                refused += 1
            held = sum(len(p) for part in proto._partial.values() for p in part.pieces.values())
            pieces = sum(len(part.pieces) for part in proto._partial.values())
            assert held <= limit and pieces * PIECE_COST <= limit
            assert proto.held_fragment_bytes <= limit
    assert refused == 200


def test_fragments_within_the_bound_still_reassemble() -> None:
    """An op exactly as large as the bound, in many pieces, reassembles."""
    op = Publish("/a", {"data": "x" * 5000})
    text = encode(op)
    pieces = split_fragments(text, PIECE_COST, "big")
    proto = Conversation(max_fragment_bytes=len(pieces) * PIECE_COST)
    results = [proto.receive(p) for p in pieces]
    assert results[-1] == op and proto.held_fragment_bytes == 0


_json = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4),
    max_leaves=12,
)
_op_like = st.fixed_dictionaries(
    {"op": st.sampled_from(["publish", "subscribe", "call_service", "advertise", "fragment",
                            "service_response", "unsubscribe", "status", "nope"])},
    optional={k: _json for k in ["topic", "msg", "id", "type", "args", "service", "result",
                                 "values", "num", "total", "data", "throttle_rate"]},
)


@settings(max_examples=300, deadline=None)
@given(st.one_of(st.text(max_size=64), st.binary(max_size=64), _op_like.map(json.dumps),
                 _op_like.map(cbor2.dumps)))
def test_any_frame_gives_an_op_or_a_protocol_error(frame: Any) -> None:
    """Fuzz: whatever arrives, the core returns an op (or None for a fragment) or raises RemoteProtocolError."""
    proto = Conversation()
    try:
        result = proto.receive(frame)
    except RemoteProtocolError as exc:
        assert exc.message
    else:
        assert result is None or parse_op(json.loads(encode(result))) == result


_JSON = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(), inner, max_size=4),
    max_leaves=12,
)


@given(_JSON, st.sampled_from(["", " ", "\n", " \t"]), st.sampled_from(["", " ", "\n", "x",
                                                                         "{}", ",", "]"]))
def test_a_text_frame_decodes_as_json_loads_decodes_it(value: Any, before: str,
                                                      after: str) -> None:
    """Any JSON value, with whitespace or anything else around it: the same value as
    json.loads, or the error naming where json.loads stops."""
    text = before + json.dumps(value) + after
    try:
        expected = json.loads(text)
    except json.JSONDecodeError as exc:
        with pytest.raises(RemoteProtocolError, match=f"at line {exc.lineno} column {exc.colno}"):
            decode_frame(text)
        return
    assert decode_frame(text) == expected
