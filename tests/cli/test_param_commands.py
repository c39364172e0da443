"""``param list/get/set/describe/dump/load/delete`` against the real bridge and an rclpy node."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.cli.conftest import Run, one_error_line
from tests.cli.ros2_nodes import full_name
from tests.cli.test_commands import until_ok

pytest.importorskip("yaml")

NAMES = ["count", "flags", "gains", "name", "nested.gain", "scratch", "speed_limit",
         "start_type_description_service", "use_sim_time"]
"""The parameters of :func:`param_node`, with the two every Jazzy rclpy node has."""


def test_param_list(cli: Run, param_node: Any) -> None:
    """param list NODE prints the names two spaces in, sorted; --param-type adds each type;
    without NODE every node's names follow a '/node:' line."""
    node = full_name(param_node)
    result = until_ok(cli, "param", "list", node, "--wait", "10")
    assert result.lines == [f"  {n}" for n in NAMES]
    typed = cli("param", "list", node, "--param-type", "--filter", "nested|count")
    assert typed.lines == ["  count (type: integer)", "  nested.gain (type: double)"]
    everyone = cli("param", "list")  # (exit 6 if a node of an earlier test is still listed)
    at = everyone.lines.index(f"{node}:")
    assert everyone.lines[at + 1:at + 1 + len(NAMES)] == [f"  {n}" for n in NAMES]


def test_param_get(cli: Run, param_node: Any) -> None:
    """param get prints ros2's 'Integer value is: 3' lines (--hide-type: the value alone)."""
    node = full_name(param_node)
    assert until_ok(cli, "param", "get", node, "count", "--wait", "10").lines == [
        "Integer value is: 3"]
    expected = {"speed_limit": "Double value is: 1.5", "name": "String value is: robot",
                "flags": "Boolean values are: [True, False]",
                "gains": "Double values are: [0.5, 1.0]", "nested.gain": "Double value is: 0.25"}
    for name, line in expected.items():
        assert cli("param", "get", node, name).lines == [line]
    assert cli("param", "get", node, "gains", "--hide-type").lines == ["[0.5, 1.0]"]
    one_error_line(cli("param", "get", node, "nope"), 4, "Parameter not set", "nope")
    one_error_line(cli("param", "get", "/no_such_node_here", "count", "--wait", "0.2"), 4,
                   "unknown node /no_such_node_here")


def test_param_set(cli: Run, param_node: Any) -> None:
    """param set types the value as ros2 does and the node takes it; a value the node refuses
    prints ros2's 'Setting parameter failed: <reason>' on stderr and exits 6."""
    node = full_name(param_node)
    result = until_ok(cli, "param", "set", node, "count", "7", "--wait", "10")
    assert result.lines == ["Set parameter successful"]
    assert param_node.get_parameter("count").value == 7
    assert cli("param", "set", node, "gains", "[2.5, 3.0]").lines == ["Set parameter successful"]
    assert list(param_node.get_parameter("gains").value) == [2.5, 3.0]
    refused = cli("param", "set", node, "count", "fast")
    assert refused.code == 6 and refused.out == "", refused
    assert refused.err.startswith("Setting parameter failed: "), refused
    assert param_node.get_parameter("count").value == 7
    read_only = cli("param", "set", node, "speed_limit", "2.0")
    assert read_only.code == 6 and "read-only" in read_only.err, read_only


def test_param_describe(cli: Run, param_node: Any) -> None:
    """param describe prints ros2's lines: type, description, read only, the range."""
    node = full_name(param_node)
    result = until_ok(cli, "param", "describe", node, "speed_limit", "count", "--wait", "10")
    assert result.lines == [
        "Parameter name: speed_limit", "  Type: double", "  Description: top speed",
        "  Constraints:", "    Read only: true", "    Min value: 0.0", "    Max value: 10.0",
        "    Step: 0.5",
        "Parameter name: count", "  Type: integer", "  Constraints:"]


def test_param_dump_then_load_round_trips(cli: Run, param_node: Any, tmp_path: Path) -> None:
    """param dump prints ros2's parameter file; changed values come back when it is loaded."""
    node = full_name(param_node)
    dump = until_ok(cli, "param", "dump", node, "--wait", "10")
    assert dump.out == (
        f"{node}:\n  ros__parameters:\n    count: 3\n    flags:\n    - true\n    - false\n"
        "    gains:\n    - 0.5\n    - 1.0\n    name: robot\n    nested:\n      gain: 0.25\n"
        "    scratch: x\n    speed_limit: 1.5\n    start_type_description_service: true\n"
        "    use_sim_time: false\n\n")
    path = tmp_path / "params.yaml"
    path.write_text(dump.out)
    param_node.set_parameters([_param("count", 9), _param("nested.gain", 0.75)])
    loaded = cli("param", "load", node, str(path))
    assert loaded.code == 6, loaded  # speed_limit is read only: its line says so on stderr
    assert "Set parameter count successful" in loaded.lines
    assert "Set parameter nested.gain successful" in loaded.lines
    assert "Set parameter speed_limit failed" in loaded.err
    assert param_node.get_parameter("count").value == 3
    assert param_node.get_parameter("nested.gain").value == 0.25


def test_param_load_a_ros2_file(cli: Run, param_node: Any, tmp_path: Path) -> None:
    """A parameter file as ros2 writes them (another node's key, '/**', nested tables) loads:
    '/**' first, the named entries after it, as ros2 param load does."""
    node = full_name(param_node)
    path = tmp_path / "ros2.yaml"
    path.write_text("/**:\n  ros__parameters:\n    count: 11\n    name: everyone\n"
                    "/some/other_node:\n  ros__parameters:\n    count: 12\n"
                    "    nested:\n      gain: 2.0\n")
    result = until_ok(cli, "param", "load", node, str(path), "--wait", "10")
    assert result.lines == ["Set parameter count successful", "Set parameter name successful",
                            "Set parameter nested.gain successful"]
    assert param_node.get_parameter("count").value == 12
    assert param_node.get_parameter("name").value == "everyone"
    assert param_node.get_parameter("nested.gain").value == 2.0
    broken = tmp_path / "broken.yaml"
    broken.write_text("/x:\n  gain: 1\n")
    one_error_line(cli("param", "load", node, str(broken)), 2, str(broken), "ros__parameters")


def test_param_delete(cli: Run, param_node: Any) -> None:
    """param delete undeclares a parameter; one the node will not undeclare says why (exit 6)."""
    node = full_name(param_node)
    result = until_ok(cli, "param", "delete", node, "scratch", "--wait", "10")
    assert result.lines == ["Deleted parameter successfully"]
    assert not param_node.has_parameter("scratch")
    refused = cli("param", "delete", node, "count")
    assert refused.code == 6 and refused.err.startswith("Deleting parameter failed"), refused
    assert param_node.has_parameter("count")


def _param(name: str, value: Any) -> Any:
    from rclpy.parameter import Parameter

    make: Any = Parameter  # rclpy is untyped
    return make(name, value=value)
