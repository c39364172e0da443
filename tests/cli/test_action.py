"""``roslibpy-lite action ...`` against the real bridge and an rclpy action server."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from roslibpy_lite.cli import EXIT_INTERRUPTED, EXIT_NOT_FOUND, EXIT_REMOTE, EXIT_USAGE
from tests.bridge.action_support import FIB, FibServer, fib
from tests.cli.conftest import Run, one_error_line
from tests.cli.test_commands import until_ok
from tests.examples.support import Program
from tests.helpers import BridgeProcess

CLI = str(Path(sys.executable).parent / "roslibpy-lite")


def test_list_type_and_info(cli: Run, ros_node: Any, topic: str) -> None:
    """list (-t, --json), type and info (with the serving node) show an rclpy action server."""
    server = FibServer(ros_node, topic)
    try:
        assert cli("action", "type", topic, "--wait", "10").lines == [FIB]
        assert f"{topic} [{FIB}]" in cli("action", "list", "-t").lines
        listed = json.loads(cli("action", "list", "--json").out)
        assert {"name": topic, "type": FIB} in listed
        # The graph names an endpoint's node a little after the endpoint itself.
        info = until_ok(cli, "action", "info", topic,
                        check=lambda r: "Action servers: 1" in r.lines).lines
        assert info[:3] == [f"Action: {topic}", f"Type: {FIB}", "Action servers: 1"]
        assert info[3].strip() == ros_node.get_fully_qualified_name()
    finally:
        server.destroy()


def test_send_goal_with_feedback(cli: Run, ros_node: Any, topic: str) -> None:
    """send_goal prints the goal, each feedback with --feedback, the result and its status."""
    server = FibServer(ros_node, topic)
    try:
        result = cli("action", "send_goal", topic, FIB, "{order: 3}", "--feedback",
                     "--wait", "10")
    finally:
        server.destroy()
    assert result.code == 0, result
    out = result.out
    assert "Sending goal:\n  order: 3\n" in out
    assert 1 <= out.count("Feedback:") <= 2  # ROS may drop feedback under load
    assert "Result:\n  sequence:\n  - 0\n  - 1\n  - 1\n  - 2\n" in out
    assert out.rstrip().endswith("Goal finished with status: SUCCEEDED")


def test_send_goal_json(cli: Run, ros_node: Any, topic: str) -> None:
    """--json prints one line per feedback and one with the status and result."""
    server = FibServer(ros_node, topic)
    try:
        result = cli("action", "send_goal", topic, "test_msgs/Fibonacci", '{"order": 2}',
                     "--feedback", "--json", "--wait", "10")
    finally:
        server.destroy()
    records = [json.loads(line) for line in result.lines]
    assert records[-1] == {"status": "SUCCEEDED", "result": {"sequence": fib(2)}}
    assert records[0] == {"feedback": {"sequence": fib(2)}}


def test_send_goal_errors(cli: Run, ros_node: Any, topic: str) -> None:
    """Unknown action, bad values and an aborted goal: one line each, distinct exit codes."""
    one_error_line(cli("action", "send_goal", topic, FIB, "{order: 3}", "--wait", "0.2"),
                   EXIT_NOT_FOUND, f"unknown action {topic}")
    one_error_line(cli("action", "send_goal", topic, FIB, "{order: three}"),
                   EXIT_USAGE, "order")
    one_error_line(cli("action", "send_goal", topic, "test_msgs/srv/Fibonacci"),
                   EXIT_USAGE, "not an action type")
    server = FibServer(ros_node, topic, abort=True)
    try:
        result = cli("action", "send_goal", topic, FIB, "{order: 2}", "--wait", "10")
    finally:
        server.destroy()
    assert result.code == EXIT_REMOTE and "Goal finished with status: ABORTED" in result.out
    assert result.err.strip() == f"roslibpy-lite: goal to {topic} ended ABORTED"


def test_ctrl_c_cancels_the_goal(bridge: BridgeProcess, ros_node: Any, topic: str) -> None:
    """Ctrl+C during send_goal cancels the goal on the rclpy server and exits 130 cleanly."""
    server = FibServer(ros_node, topic, slow=True)
    goal = Program([CLI, "action", "send_goal", topic, FIB, "{order: 1}", "--feedback",
                    "--wait", "10", "--url", bridge.url])
    try:
        goal.wait_for(r"^Feedback:$")
    finally:
        code = goal.interrupt()
        server.destroy()
    assert code == EXIT_INTERRUPTED, goal.dump()
    assert server.cancel_requests.is_set()
    assert goal.err == ["Canceling goal...", "Goal canceled."], goal.dump()
