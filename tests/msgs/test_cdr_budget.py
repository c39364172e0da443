"""msgs.cdr's decode budget (issue 53): a valid message costs at most ``max(floor, per_byte *
its size)`` decoded, refused before the elements over it are made, naming the field and the
budget; real sensor messages pass, and every decoding entry point (``decode``, typed
decoders, ``cdr_json``, ``cdr_columns``) keeps it."""

from __future__ import annotations

import struct
import tracemalloc
from collections.abc import Iterator

import cbor2
import pytest

from msgs import cdr, cdr_columns
from msgs.runtime import Message, lookup_message
from rosbridge_core.codec import cdr_json
from tests.msgs.test_cdr_bounds import _struct

MIB = 2**20


@pytest.fixture
def budget() -> Iterator[None]:
    """Whatever a test sets, the default budget after it."""
    yield
    cdr.set_budget(cdr.DEFAULT_BUDGET)


def _sequence_of(element: str, count: int, each: bytes) -> tuple[type[Message], bytes]:
    """A type of one sequence of ``element``, and a message of ``count`` elements ``each``
    (doubles aligned to 8 from the header's end)."""
    cls = lookup_message(_struct([f"{element}[]"]))
    pad = bytes(4) if count and element.startswith("geometry_msgs") else b""
    data = b"\x00\x01\x00\x00" + struct.pack("<I", count) + pad + each * count
    cdr.decode(b"\x00\x01\x00\x00" + bytes(4), cls)  # compiled before anything is measured
    return cls, data


def _peak(fn: object, *args: object) -> tuple[object, int]:
    """What ``fn(*args)`` gives (or raises), and the peak of memory it took."""
    tracemalloc.start()
    try:
        try:
            out = fn(*args)  # type: ignore[operator]
        except Exception as exc:
            out = exc
        return out, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_the_red_teams_bomb_fails_at_its_count_naming_the_field_and_the_budget() -> None:
    """8 MiB of one-byte structs (~1.7 GB decoded) fail at their sequence's count, naming
    the field, the cost and the budget, having taken almost nothing."""
    cls, data = _sequence_of(_struct(["uint8"]), 8 * MIB, b"\x07")
    out, peak = _peak(cdr.decode, data, cls)
    assert isinstance(out, cdr.BudgetError), out
    assert peak < 64 * 1024
    assert str(out) == (
        f"{cls._type}: cannot decode field 'f0' from CDR: its {8 * MIB} elements would cost "
        f"about 1648.0 MiB decoded (206 bytes each), over the decode budget of 128.0 MiB for "
        "a message of 8.0 MiB (16 times its size, at least 32.0 MiB)")


@pytest.mark.parametrize(("element", "each", "count"), [
    ("", b"\x00", 4 * MIB),  # empty structs (their placeholder byte)
    ("uint8", b"\x01", 4 * MIB),
    ("int8", b"\x9c", 4 * MIB),  # -100: an int object each, not CPython's shared small ones
])
def test_cheap_elements_over_the_budget_are_refused(element: str, each: bytes,
                                                    count: int) -> None:
    """Millions of empty structs, one-byte structs or negative int8s: each refused with a BudgetError, within a small peak (int8s: their bytes, counted)."""
    spec = element if element == "int8" else _struct([element] if element else [])
    cls, data = _sequence_of(spec, count, each)
    out, peak = _peak(cdr.decode, data, cls)
    assert isinstance(out, cdr.BudgetError), out
    assert peak < (2 * len(data) if element == "int8" else 0) + 64 * 1024


def test_real_sensor_messages_pass() -> None:
    """A 4 MiB PointCloud2, a 1080p rgb8 Image, a 1000x1000 OccupancyGrid and a 1000-beam
    LaserScan decode, as wire dicts, typed, as JSON and as rows."""
    cloud = lookup_message("sensor_msgs/msg/PointCloud2").from_json({
        "height": 1, "width": 4 * MIB // 16, "point_step": 16, "row_step": 4 * MIB,
        "fields": [{"name": n, "offset": 4 * i, "datatype": 7, "count": 1}
                   for i, n in enumerate("xyz")], "data": bytes(4 * MIB)})
    image = lookup_message("sensor_msgs/msg/Image").from_json({
        "height": 1080, "width": 1920, "encoding": "rgb8", "step": 5760,
        "data": bytes(1920 * 1080 * 3)})
    grid = lookup_message("nav_msgs/msg/OccupancyGrid").from_json({
        "info": {"width": 1000, "height": 1000}, "data": [-1, 0, 100, 50] * 250_000})
    scan = lookup_message("sensor_msgs/msg/LaserScan").from_json({
        "ranges": [1.5] * 1000, "intensities": [0.5] * 1000})
    for msg in (cloud, image, grid, scan):
        cls, data = type(msg), cdr.encode(msg)
        assert len(cdr.decode(data, cls)) == len(cls._fields_and_types)
        cdr.decoder_for(cls, typed=cbor2.CBORTag)(data)
        assert cdr_json.msgs_encoder(cls)(data) is not None
        names = [name for name, _ in cdr_columns.leaf_names(cls)]
        assert len(cdr_columns.row_decoder(cls, names)(data)) == len(names)


@pytest.mark.parametrize(("element", "each"), [
    ("geometry_msgs/Point", struct.pack("<3d", 1.5, 2.5, 3.5)),
    ("geometry_msgs/Pose", struct.pack("<7d", *(i / 3 for i in range(7)))),
    ("int16", struct.pack("<h", 30000)),
    ("string", b"\x03\x00\x00\x00ab\x00\x00"),
])
def test_what_a_decode_takes_is_within_the_budgets_estimate(element: str, each: bytes) -> None:
    """Messages costing 1 MiB (points, poses, int16s, strings) decode taking no more memory
    than the budget's estimate of them, and two passing copies of their bytes."""
    cost = 8 + cdr.element_cost(element)
    count = MIB // cost
    cls, data = _sequence_of(element, count, each)
    out, peak = _peak(cdr.decode, data, cls)
    assert isinstance(out, dict), out
    assert peak <= count * cost + 2 * len(data) + 64 * 1024, (peak, count * cost)


def test_the_budget_is_configurable_and_kept_by_every_entry_point(budget: None) -> None:
    """A budget of 1 byte per byte and no floor refuses 100 points (24 bytes each, ~300
    decoded) from decode, typed decoders, cdr_json (None: the converter says why) and
    row decoders; the default takes them."""
    cls, data = _sequence_of("geometry_msgs/Point", 100, bytes(24))  # 2412 bytes
    cdr.set_budget(cdr.Budget(per_byte=1, floor=0))
    with pytest.raises(cdr.BudgetError, match=r"'f0' from CDR: its 100 elements .* over the "
                       r"decode budget of 2412 bytes for a message of 2412 bytes \(1 times"):
        cdr.decode(data, cls)
    with pytest.raises(cdr.BudgetError):
        cdr.decoder_for(cls, typed=cbor2.CBORTag)(data)
    assert cdr_json.msgs_encoder(cls)(data) is None
    with pytest.raises(ValueError, match="over the decode budget"):
        cdr_columns.row_decoder(cls, ["f0"])(data)
    cdr.set_budget(cdr.DEFAULT_BUDGET)
    assert len(cdr.decode(data, cls)["f0"]) == 100
    with pytest.raises(ValueError, match="per_byte >= 1"):
        cdr.set_budget(cdr.Budget(per_byte=0))


def test_nested_sequences_are_charged_as_they_are_read(budget: None) -> None:
    """Sequences inside the elements of a sequence take from the same budget: 100 structs of
    100 empty ones each pass one at a time and fail together, naming the path."""
    inner = _struct([f"{_struct([])}[]"])
    cls = lookup_message(_struct([f"{inner}[]"]))
    one = struct.pack("<I", 100) + bytes(100)
    data = b"\x00\x01\x00\x00" + struct.pack("<I", 100) + one * 100
    cdr.set_budget(cdr.Budget(per_byte=16, floor=0))
    with pytest.raises(cdr.BudgetError, match=r"'f0\.f0' from CDR: its 100 elements would "
                       r"cost about 7200 bytes decoded \(72 bytes each\), over the decode "
                       r"budget of .* of which"):
        cdr.decode(data, cls)
    cdr.set_budget(cdr.Budget(per_byte=200, floor=0))
    assert len(cdr.decode(data, cls)["f0"]) == 100
