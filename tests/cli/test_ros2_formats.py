"""The output and file formats of the ros2-like commands, held to samples written from ros2cli's
sources (ros2/ros2cli 0.36: ros2param/verb/*.py and api, ros2topic/verb/bw.py and delay.py,
ros2lifecycle/verb/*.py) and rclpy's ``get_parameter_value``; no bridge needed."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from roslibpy_lite.cli.format import ArgumentError
from roslibpy_lite.cli.lifecycle import _transition_lines
from roslibpy_lite.cli.param import _describe_lines
from roslibpy_lite.cli.paramvalue import (
    ParameterFileError,
    dump_yaml,
    get_line,
    guess_value,
    parameters_from_yaml,
    to_python,
)
from roslibpy_lite.cli.topic_stats import (
    BandwidthStats,
    DelayStats,
    bw_text,
    delay_text,
    stamp_ns,
)

pytest.importorskip("yaml")

# ``ros2 param dump /talker`` of a node with these parameters, as ros2param's DumpVerb prints
# it (yaml.dump(..., default_flow_style=False): keys sorted, block lists, nested names nested).
DUMP_SAMPLE = """\
/talker:
  ros__parameters:
    count: 3
    flags:
    - true
    - false
    gains:
    - 0.5
    - 1.0
    name: robot
    nested:
      gain: 0.25
      label: '5'
    speed_limit: 1.5
    use_sim_time: false

"""

VALUES: dict[str, dict[str, Any]] = {
    "count": {"type": 2, "integer_value": 3},
    "flags": {"type": 6, "bool_array_value": [True, False]},
    "gains": {"type": 8, "double_array_value": [0.5, 1.0]},
    "name": {"type": 4, "string_value": "robot"},
    "nested.gain": {"type": 3, "double_value": 0.25},
    "nested.label": {"type": 4, "string_value": "5"},
    "speed_limit": {"type": 3, "double_value": 1.5},
    "use_sim_time": {"type": 1, "bool_value": False},
}


def test_dump_is_ros2_param_dumps_text() -> None:
    """param dump prints ros2's parameter file (with print's extra blank line) for the values."""
    text = dump_yaml("/talker", {n: to_python(v) for n, v in VALUES.items()})
    assert text + "\n" == DUMP_SAMPLE


def test_a_ros2_dump_loads_with_its_types(tmp_path: Path) -> None:
    """A file in ros2 param dump's format loads to the same names and ParameterValue types."""
    loaded = dict(parameters_from_yaml(DUMP_SAMPLE, "params.yaml"))
    assert loaded == VALUES


def test_load_puts_the_wildcard_first_and_merges_every_entry() -> None:
    """As ros2 param load: '/**' is set first (a node's entry overrides it), every node entry
    of the file is loaded, and --no-use-wildcard leaves '/**' out."""
    text = ("/talker:\n  ros__parameters:\n    gain: 2.0\n"
            "/**:\n  ros__parameters:\n    gain: 1.0\n    shared: yes\n")
    assert parameters_from_yaml(text, "f") == [
        ("gain", {"type": 3, "double_value": 2.0}), ("shared", {"type": 1, "bool_value": True})]
    assert parameters_from_yaml(text, "f", use_wildcard=False) == [
        ("gain", {"type": 3, "double_value": 2.0})]


@pytest.mark.parametrize(("text", "fragment"), [
    ("[1, 2", "f is not valid YAML at line 1"),
    ("- a\n- b\n", "expected a mapping of node names"),
    ("/talker:\n  gain: 1\n", "the entry '/talker' has no 'ros__parameters'"),
    ("/talker:\n  ros__parameters:\n    mixed: [1, a]\n", "f: parameter mixed: a list"),
])
def test_bad_parameter_files_say_what_is_wrong(text: str, fragment: str) -> None:
    """A file not in ros2's format is refused with its name and the entry at fault."""
    with pytest.raises(ParameterFileError, match=None) as caught:
        parameters_from_yaml(text, "f")
    assert fragment in str(caught.value)
    assert isinstance(caught.value, ArgumentError)


@pytest.mark.parametrize(("text", "wire"), [
    ("5", {"type": 2, "integer_value": 5}),
    ("5.0", {"type": 3, "double_value": 5.0}),
    ("true", {"type": 1, "bool_value": True}),
    ("hello", {"type": 4, "string_value": "hello"}),
    ("[1, 2]", {"type": 7, "integer_array_value": [1, 2]}),
    ("[0.5, 1.5]", {"type": 8, "double_array_value": [0.5, 1.5]}),
    ("[a, b]", {"type": 9, "string_array_value": ["a", "b"]}),
    ("[true, false]", {"type": 6, "bool_array_value": [True, False]}),
    ("[1, a]", {"type": 4, "string_value": "[1, a]"}),
    ("{a: 1}", {"type": 4, "string_value": "{a: 1}"}),
    ("", {"type": 4, "string_value": ""}),
])
def test_set_types_a_value_as_rclpy_does(text: str, wire: dict[str, object]) -> None:
    """param set's VALUE is typed as rclpy.parameter.get_parameter_value types the text."""
    assert guess_value(text) == wire


@pytest.mark.parametrize(("value", "line"), [
    ({"type": 1, "bool_value": True}, "Boolean value is: True"),
    ({"type": 2, "integer_value": 3}, "Integer value is: 3"),
    ({"type": 3, "double_value": 1.5}, "Double value is: 1.5"),
    ({"type": 4, "string_value": "robot"}, "String value is: robot"),
    ({"type": 5, "byte_array_value": "AQI="}, "Byte values are: [b'\\x01', b'\\x02']"),
    ({"type": 6, "bool_array_value": [True]}, "Boolean values are: [True]"),
    ({"type": 7, "integer_array_value": [1, 2]}, "Integer values are: [1, 2]"),
    ({"type": 8, "double_array_value": [0.5]}, "Double values are: [0.5]"),
    ({"type": 9, "string_array_value": ["a"]}, "String values are: ['a']"),
    ({"type": 0}, "Parameter not set."),
])
def test_get_prints_ros2_param_gets_line(value: dict[str, object], line: str) -> None:
    """param get prints ros2's label and value for each ParameterType."""
    assert get_line(value) == line
    assert get_line(value, hide_type=True) == (line.split(": ", 1)[1] if ": " in line
                                                else "None")


def test_describe_prints_ros2_param_describes_lines() -> None:
    """param describe prints name, type, description and constraints as ros2 does."""
    descriptor = {"name": "speed_limit", "type": 3, "description": "top speed",
                  "additional_constraints": "m/s", "read_only": True,
                  "floating_point_range": [{"from_value": 0, "to_value": 10, "step": 0.5}],
                  "integer_range": []}
    assert _describe_lines(descriptor) == [
        "Parameter name: speed_limit", "  Type: double", "  Description: top speed",
        "  Constraints:", "    Read only: true", "    Min value: 0.0", "    Max value: 10.0",
        "    Step: 0.5", "    Additional constraints: m/s"]
    assert _describe_lines({"name": "count", "type": 2}) == [
        "Parameter name: count", "  Type: integer", "  Constraints:"]


def test_bw_prints_ros2_topic_bws_lines() -> None:
    """topic bw: the bandwidth over the window in B, KB or MB (1000s), as ros2 prints it."""
    stats = BandwidthStats(window=100)
    for i in range(10):
        stats.add(float(i) / 10, 1009)  # ten messages of 1009 bytes, 0.1 s apart
    report = stats.report(1.0)
    assert report is not None
    assert bw_text(report) == ("10.09 KB/s from 10 messages\n"
                               "\tMessage size mean: 1.01 KB min: 1.01 KB max: 1.01 KB")
    small = BandwidthStats(window=2)
    for t, size in ((0.0, 10), (1.0, 20), (2.0, 30)):  # the window keeps the last two
        small.add(t, size)
    report = small.report(3.0)
    assert report is not None
    assert bw_text(report) == "25 B/s from 2 messages\n\tMessage size mean: 25 B min: 20 B max: 30 B"
    big = BandwidthStats(window=10)
    big.add(0.0, 2_000_000)
    big.add(0.5, 2_000_000)
    report = big.report(1.0)
    assert report is not None and bw_text(report).startswith("4.00 MB/s from 2 messages\n")
    assert BandwidthStats(5).report(1.0) is None


def test_delay_prints_ros2_topic_delays_lines() -> None:
    """topic delay: arrival minus header stamp, the first message only starting the count."""
    stats = DelayStats(window=10)
    second = 1_000_000_000
    stats.add(10 * second, 5 * second)  # the first: not counted, as in ros2
    assert stats.report() is None
    stats.add(11 * second, 11 * second - second // 10)
    stats.add(12 * second, 12 * second - 3 * second // 10)
    report = stats.report()
    assert report is not None
    assert delay_text(report) == ("average delay: 0.200\n"
                                  "\tmin: 0.100s max: 0.300s std dev: 0.10000s window: 2")
    assert stats.report() is None  # nothing new: ros2 prints "no new messages"


def test_delay_needs_a_header() -> None:
    """A message without header.stamp is refused with the topic and type named."""
    assert stamp_ns({"header": {"stamp": {"sec": 2, "nanosec": 5}}}, "/t", "T") == 2_000_000_005
    with pytest.raises(Exception, match=r"topic delay /t: its messages \(std_msgs/msg/String\)"):
        stamp_ns({"data": "x"}, "/t", "std_msgs/msg/String")


def test_lifecycle_list_prints_ros2s_three_lines() -> None:
    """lifecycle list: '- label [id]', then the start and goal states on tabbed lines."""
    t = {"transition": {"id": 1, "label": "configure"},
         "start_state": {"id": 1, "label": "unconfigured"},
         "goal_state": {"id": 10, "label": "configuring"}}
    assert _transition_lines(t) == ["- configure [1]", "\tStart: unconfigured",
                                    "\tGoal: configuring"]
