"""The CLI's text in and out: YAML/JSON arguments and the ros2-style YAML output (no network)."""

from __future__ import annotations

import math
import sys
from typing import Any

import pytest
import yaml
from hypothesis import given
from hypothesis import strategies as st

from roslibpy_lite.cli.format import ArgumentError, have_yaml, parse_values, to_yaml


def test_parse_values_reads_yaml_flow_and_block_mappings() -> None:
    """ros2-style flow YAML, block YAML and JSON all give the same mapping."""
    assert parse_values("{x: 2.5, y: 4.0}") == {"x": 2.5, "y": 4.0}
    assert parse_values("x: 2.5\ny: 4.0") == {"x": 2.5, "y": 4.0}
    assert parse_values('{"x": 2.5, "y": 4.0}') == {"x": 2.5, "y": 4.0}
    assert parse_values("{data: hello, header: {frame_id: map}}") == {
        "data": "hello", "header": {"frame_id": "map"}}


def test_parse_values_empty_is_an_empty_mapping() -> None:
    """No text, blank text and YAML null all mean {}."""
    assert parse_values(None) == {}
    assert parse_values("  ") == {}
    assert parse_values("~") == {}


def test_parse_values_rejects_bad_yaml_with_the_position() -> None:
    """Unparsable YAML names the line and column."""
    with pytest.raises(ArgumentError, match=r"VALUES is not valid YAML at line 1, column \d+"):
        parse_values("{x: [1")


def test_parse_values_rejects_non_mappings() -> None:
    """A list or a scalar is refused with what was given."""
    with pytest.raises(ArgumentError, match=r"must be a mapping .* got list '\[1, 2\]'"):
        parse_values("[1, 2]")
    with pytest.raises(ArgumentError, match="got int '5'"):
        parse_values("5", "VALUES")


def test_parse_values_without_pyyaml_accepts_json_only(monkeypatch: pytest.MonkeyPatch) -> None:
    """Without PyYAML, JSON still works and YAML gets a message saying how to get YAML."""
    monkeypatch.setitem(sys.modules, "yaml", None)
    assert not have_yaml()
    assert parse_values('{"x": 1.5}') == {"x": 1.5}
    with pytest.raises(ArgumentError, match=r"not valid JSON .*only JSON .*pip install pyyaml"):
        parse_values("{x: 1.5}")


def test_to_yaml_looks_like_ros2_echo() -> None:
    """Nested fields indent by two, strings are single-quoted, sequences are block lists."""
    msg = {"header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "map"},
           "data": [1.5, 2.0], "name": "it's", "empty": [], "flag": True}
    assert to_yaml(msg) == (
        "header:\n"
        "  stamp:\n"
        "    sec: 1\n"
        "    nanosec: 2\n"
        "  frame_id: 'map'\n"
        "data:\n"
        "- 1.5\n"
        "- 2.0\n"
        "name: 'it''s'\n"
        "empty: []\n"
        "flag: true"
    )


def test_to_yaml_lists_of_messages_and_no_arr() -> None:
    """Lists of messages use '- key: value'; --no-arr shows sequence lengths instead."""
    msg = {"points": [{"x": 1.0, "y": 2.0}, {"x": 3.0, "y": 4.0}]}
    assert to_yaml(msg) == "points:\n- x: 1.0\n  y: 2.0\n- x: 3.0\n  y: 4.0"
    assert to_yaml(msg, no_arr=True) == "points: '<sequence, length: 2>'"


def test_to_yaml_special_floats_and_strings() -> None:
    """NaN/Inf use YAML's spellings; control characters are escaped in double quotes."""
    out = to_yaml({"a": math.nan, "b": -math.inf, "c": "line\nbreak", "d": None})
    assert yaml.safe_load(out)["c"] == "line\nbreak"
    assert out.splitlines()[:2] == ["a: .nan", "b: -.inf"]
    assert out.splitlines()[-1] == "d: null"


_scalars = (st.none() | st.booleans() | st.integers(-(2**63), 2**64)
            | st.floats(allow_nan=False, allow_infinity=False) | st.text(max_size=20))
_keys = st.text(min_size=1, max_size=10)
_values: Any = st.recursive(
    _scalars,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(_keys, inner, max_size=4),
    max_leaves=20,
)


@given(st.dictionaries(_keys, _values, max_size=5))
def test_to_yaml_round_trips_through_a_yaml_parser(value: dict[str, Any]) -> None:
    """Whatever a message holds, PyYAML reads back exactly the same value from to_yaml."""
    assert yaml.safe_load(to_yaml(value)) == value
