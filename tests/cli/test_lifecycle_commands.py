"""``lifecycle nodes/get/list/set`` against the real bridge and an rclpy LifecycleNode."""

from __future__ import annotations

from typing import Any

from tests.cli.conftest import Run, one_error_line
from tests.cli.ros2_nodes import full_name
from tests.cli.test_commands import until_ok


def test_lifecycle_nodes_lists_managed_nodes_only(cli: Run, managed_node: Any,
                                                  ros_node: Any) -> None:
    """lifecycle nodes names the LifecycleNode and not a plain node; -c counts them."""
    node = full_name(managed_node)
    result = until_ok(cli, "lifecycle", "nodes", check=lambda r: node in r.lines)
    assert full_name(ros_node) not in result.lines
    assert result.lines == sorted(result.lines)
    count = cli("lifecycle", "nodes", "-c")
    assert count.lines == [str(len(result.lines))]


def test_lifecycle_get_and_set(cli: Run, managed_node: Any) -> None:
    """get prints 'unconfigured [1]'; set configure, then activate (by id), moves the node:
    'Transitioning successful', and get follows; without NODE get prefixes '/node: '."""
    node = full_name(managed_node)
    assert until_ok(cli, "lifecycle", "get", node, "--wait", "10").lines == ["unconfigured [1]"]
    assert f"{node}: unconfigured [1]" in cli("lifecycle", "get").lines
    assert cli("lifecycle", "set", node, "configure").lines == ["Transitioning successful"]
    assert cli("lifecycle", "get", node).lines == ["inactive [2]"]
    assert cli("lifecycle", "set", node, "3").lines == ["Transitioning successful"]  # activate
    assert cli("lifecycle", "get", node).lines == ["active [3]"]
    assert managed_node._state_machine.current_state[1] == "active"


def test_lifecycle_list(cli: Run, managed_node: Any) -> None:
    """list prints the transitions from the current state as ros2 does; -a every one."""
    node = full_name(managed_node)
    result = until_ok(cli, "lifecycle", "list", node, "--wait", "10")
    assert result.lines == ["- configure [1]", "\tStart: unconfigured", "\tGoal: configuring",
                            "- shutdown [5]", "\tStart: unconfigured", "\tGoal: shuttingdown"]
    everything = cli("lifecycle", "list", node, "-a")
    assert everything.code == 0, everything
    labels = [line for line in everything.lines if line.startswith("- ")]
    assert len(labels) > 2 and "- activate [3]" in labels


def test_lifecycle_refusals(cli: Run, managed_node: Any, ros_node: Any) -> None:
    """An unknown transition lists the available ones (exit 2); a plain node is not a
    lifecycle node (exit 4)."""
    node = full_name(managed_node)
    until_ok(cli, "lifecycle", "get", node, "--wait", "10")
    one_error_line(cli("lifecycle", "set", node, "fly"), 2,
                   "Unknown transition requested, available ones are: configure [1], "
                   "shutdown [5]")
    plain = full_name(ros_node)
    until_ok(cli, "node", "list", check=lambda r: plain in r.lines)
    one_error_line(cli("lifecycle", "get", plain), 4, f"{plain} is not a lifecycle node")
