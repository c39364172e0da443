"""msgs.cdr is bounded by its input: whatever the bytes claim (a sequence's count of 2^32-1,
a fixed array of empty messages), decoding costs memory in proportion to the bytes and ends,
with the value or a CdrError naming the type, the field and what was wrong."""

from __future__ import annotations

import itertools
import signal
import struct
import tracemalloc
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import cbor2
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from msgs import cdr, dynamic
from msgs.runtime import Message, lookup_message
from msgs.test_msgs.msg import UnboundedSequences
from rosbridge_core.codec import cdr_json
from tests.msgs.test_cdr import _message

PER_BYTE = 256
"""Bytes a decoded value may take per byte of input (the worst is a message of one
``uint8`` per element of a sequence: a dict of one entry, ~200 bytes, per byte)."""
SLACK = 64 * 1024
"""Bytes any decode may take besides (the decoder's frames, its error text)."""
HANG = 10.0
"""Seconds after which a decode is taken as looping for ever (none takes a millisecond)."""

_NAMES = itertools.count()
_PRIMITIVE = ["bool", "byte", "char", "uint8", "int16", "uint32", "int64", "float64",
              "string", "string<=3"]
_SHIPPED = ["test_msgs/msg/UnboundedSequences", "test_msgs/msg/Arrays",
            "test_msgs/msg/BoundedSequences", "test_msgs/msg/MultiNested",
            "test_msgs/msg/WStrings", "sensor_msgs/msg/PointCloud2", "sensor_msgs/msg/Imu",
            "std_msgs/msg/Empty", "visualization_msgs/msg/MarkerArray"]


class Runaway(AssertionError):
    """A decode took more memory than its bound, or did not end."""


@contextmanager
def bounded(limit: int) -> Iterator[Callable[[], int]]:
    """Fail with Runaway as soon as the block allocates more than ``limit`` bytes (checked
    every 10 ms, so a runaway decode is stopped near its bound instead of taking the machine)
    or runs past HANG; gives a function returning the block's peak allocation."""
    tracemalloc.start()
    start = tracemalloc.get_traced_memory()[0]
    tracemalloc.reset_peak()
    ticks = 0

    def check(_signum: int, _frame: Any) -> None:
        nonlocal ticks
        ticks += 1
        used = tracemalloc.get_traced_memory()[0] - start
        if used > limit:
            raise Runaway(f"{used} bytes allocated, over the bound of {limit}")
        if ticks * 0.01 > HANG:
            raise Runaway(f"still decoding after {HANG} s")

    old = signal.signal(signal.SIGALRM, check)
    signal.setitimer(signal.ITIMER_REAL, 0.01, 0.01)
    try:
        yield lambda: tracemalloc.get_traced_memory()[1] - start
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
        tracemalloc.stop()


def assert_bounded(cls: type[Message], data: bytes) -> None:
    """``data`` decodes as ``cls`` (to a dict, with typed arrays for CBOR, and to JSON text)
    or fails with CdrError, in memory within PER_BYTE times its size."""
    decoders = [cdr.decoder_for(cls), cdr.decoder_for(cls, typed=cbor2.CBORTag)]  # compiled
    to_json = cdr_json.msgs_encoder(cls)  # before measuring
    limit = PER_BYTE * len(data) + SLACK
    with bounded(limit) as peak:
        for decode in decoders:
            try:
                assert isinstance(decode(data), dict)
            except cdr.CdrError as exc:
                assert str(exc).startswith(f"{cls._type}: cannot decode ")
        to_json(data)  # text, or None where the converter must do it
    assert peak() <= limit


# -- random types -----------------------------------------------------------------------------


def _struct(fields: list[str]) -> str:
    """A new message type with these field types (none: an empty message); its name."""
    name = f"cdrbounds/msg/T{next(_NAMES)}"
    dynamic.load(name, "".join(f"{spec} f{i}\n" for i, spec in enumerate(fields)))
    return name


def _element() -> st.SearchStrategy[str]:
    """A field's element type: a primitive, or a new message of random fields (often none)."""
    leaf = st.sampled_from(_PRIMITIVE) | st.just("").map(lambda _: _struct([]))
    return st.recursive(leaf, lambda inner: st.lists(_spec(inner), max_size=4).map(_struct),
                        max_leaves=6)


def _spec(element: st.SearchStrategy[str]) -> st.SearchStrategy[str]:
    """A field of ``element``s: one, a sequence, a bounded one, or a fixed array."""
    return st.tuples(element, st.sampled_from(["", "[]", "[<=2]", "[1]", "[3]", "[9]"])
                     ).map("".join)


_EMPTY = _struct([])
_ATTACKS = [_struct([f"{_EMPTY}[]"]), _struct(["int32", f"{_EMPTY}[<=2]", f"{_EMPTY}[9]"]),
            _struct(["string", _struct([f"{_EMPTY}[]", "uint8[]"]) + "[]"])]
"""Types of the attacks (issue 39): sequences of empty messages, alone and nested."""

_types = st.one_of(
    st.lists(_spec(_element()), max_size=5).map(_struct),
    st.sampled_from(_SHIPPED + _ATTACKS),
).map(lookup_message)


@st.composite
def _payloads(draw: st.DrawFn, cls: type[Message]) -> bytes:
    """Bytes for ``cls``: random ones, or a real message's with a count overwritten by a
    random (often huge) number, or cut short."""
    head = b"\x00\x01\x00\x00"
    if draw(st.booleans()):
        return head + draw(st.binary(max_size=64))
    data = bytearray(cdr.encode(draw(_message(cls))))
    if len(data) > 4 and draw(st.booleans()):
        at = draw(st.integers(4, len(data) - 1)) & ~3
        data[at:at + 4] = struct.pack("<I", draw(st.sampled_from(
            [2**32 - 1, 2**31, 30_000_000, 65_536]) | st.integers(0, 2**32 - 1)))
    cut = draw(st.integers(4, len(data)))
    return bytes(data[:cut])


@settings(max_examples=80, deadline=None, suppress_health_check=[
    HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much])
@given(data=st.data())
def test_any_bytes_against_any_type_decode_within_a_multiple_of_their_size(
    data: st.DataObject,
) -> None:
    """Arbitrary bytes against random types (empty, nested, sequences and fixed arrays of
    empty messages) and shipped ones: a value or a CdrError, in memory bounded by the size."""
    cls = data.draw(_types)
    assert_bounded(cls, data.draw(_payloads(cls)))


# -- the attacks of issue 39 ------------------------------------------------------------------


def bomb(count: int) -> bytes:
    """The 73 bytes of an UnboundedSequences whose constants_values (of test_msgs/Constants,
    which has no fields) claims ``count`` elements."""
    before = list(UnboundedSequences._fields_and_types).index("constants_values")
    return b"\x00\x01\x00\x00" + bytes(4 * before) + struct.pack("<I", count) + bytes(5)


@pytest.mark.parametrize("count", [30_000_000, 2**32 - 1])
def test_a_huge_count_of_empty_messages_fails_at_once_naming_the_field(count: int) -> None:
    """The Foxglove bomb: 73 bytes claiming 3x10^7 (or 2^32-1) empty messages fail at once,
    naming the field and the count, within the memory bound."""
    data = bomb(count)
    assert len(data) == 73
    with bounded(PER_BYTE * len(data) + SLACK), pytest.raises(
            cdr.CdrError, match=rf"UnboundedSequences: cannot decode field 'constants_values' "
            rf"from CDR: claims {count} elements of at least 1 byte each, but 5 bytes are left"):
        cdr.decode(data, UnboundedSequences)
    assert_bounded(UnboundedSequences, data)


def test_a_fixed_array_of_empty_messages_needs_its_bytes() -> None:
    """The relay's case: ``E[] items`` and ``E[4000000] items`` of an empty ``E``, in 8 bytes,
    fail naming the field; as many placeholder bytes as elements decode."""
    many = lookup_message(_struct([f"{_struct([])}[]"]))
    with pytest.raises(cdr.CdrError, match=r"'f0' from CDR: claims 4294967295 elements"):
        cdr.decode(b"\x00\x01\x00\x00\xff\xff\xff\xff", many)
    fixed = lookup_message(_struct([f"{_struct([])}[4000000]"]))
    with pytest.raises(cdr.CdrError, match=r"'f0' from CDR: claims 4000000 elements of at "
                       r"least 1 byte each, but 4 bytes are left"):
        cdr.decode(b"\x00\x01\x00\x00\x00\x00\x00\x00", fixed)
    assert cdr.decode(b"\x00\x01\x00\x00\x03\x00\x00\x00\x00\x00\x00", many) == {
        "f0": [{}, {}, {}]}
    with pytest.raises(cdr.CdrError, match=r"'f0' from CDR: claims 3 elements"):
        cdr.decode(b"\x00\x01\x00\x00\x03\x00\x00\x00\x00\x00", many)


def test_an_empty_message_needs_its_placeholder_byte() -> None:
    """An empty message with no placeholder byte is truncated (not decoded past the end)."""
    empty = lookup_message("std_msgs/msg/Empty")
    assert cdr.decode(b"\x00\x01\x00\x00\x00", empty) == {}
    with pytest.raises(cdr.CdrError, match="std_msgs/msg/Empty: cannot decode the message "
                       "from CDR: truncated"):
        cdr.decode(b"\x00\x01\x00\x00", empty)


def test_nested_counts_name_the_path_and_a_bound_is_kept() -> None:
    """A lying count inside a nested message names the path through it; a bounded sequence's
    count over its bound is refused."""
    inner = _struct([f"{_struct([])}[]"])
    outer = lookup_message(_struct([inner, "int32[<=2]"]))
    with pytest.raises(cdr.CdrError, match=r"'f0\.f0' from CDR: claims 1000 elements"):
        cdr.decode(b"\x00\x01\x00\x00" + struct.pack("<I", 1000) + bytes(8), outer)
    with pytest.raises(cdr.CdrError, match=r"'f1' from CDR: claims 3 elements, over the "
                       r"sequence's bound of 2"):
        cdr.decode(b"\x00\x01\x00\x00" + struct.pack("<II", 0, 3) + bytes(12), outer)


def test_min_size_counts_what_every_element_must_take() -> None:
    """The fewest bytes per type: primitives their size, strings length and NUL, a sequence
    its count, an empty message its placeholder byte, nested and fixed arrays their sum."""
    assert [cdr.min_size(s) for s in ("uint8", "double", "string",
                                      "wstring", "sequence<int32>", "int16[3]")] == [
        1, 8, 5, 4, 4, 6]
    assert cdr.min_size("test_msgs/Constants") == 1
    assert cdr.min_size("test_msgs/Constants[7]") == 7
    assert cdr.min_size("builtin_interfaces/Time") == 8
    assert cdr.min_size("std_msgs/Header") == 13
