"""The README's code runs as written: each marked Python block, as a user would run it."""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

from robot_msgs.msg import Status as RosStatus

from tests.helpers import ROOT, BridgeProcess, marked_blocks, run_snippet

MARKED = marked_blocks(ROOT / "README.md", "readme-test")
BLOCKS = dict(reversed(MARKED))  # the first block of each kind
ACTIONS = next(code for kind, code in MARKED if kind == "bridge" and "send_goal" in code)


def test_readme_has_its_examples() -> None:
    """The README carries its tested examples: asyncio, MockRos, the blocking client and
    recording."""
    assert set(BLOCKS) == {"bag", "bridge", "mock", "sync"}


def test_client_example_runs_against_the_bridge(bridge: BridgeProcess) -> None:
    """The client example serves and calls a service and gets a latched typed message."""
    out = run_snippet(BLOCKS["bridge"], bridge)
    assert "2.5 * 4.0 = 10.0" in out
    assert "got Int16(data=3)" in out


def test_mock_example_runs() -> None:
    """The MockRos example passes its own assertion."""
    assert "MockRos test passed" in run_snippet(BLOCKS["mock"])


def test_blocking_example_runs_against_the_bridge(bridge: BridgeProcess) -> None:
    """The blocking-client example serves, calls and hears a message without async/await."""
    out = run_snippet(BLOCKS["sync"], bridge)
    assert "6 * 7 = 42.0" in out
    assert "heard {'data': 'hello'}" in out


def test_actions_example_runs_against_the_bridge(bridge: BridgeProcess) -> None:
    """The actions example serves /readme_integrate_imu, sends it a goal, hears feedback and result."""
    out = run_snippet(ACTIONS, bridge)
    assert out.count("running sum:") == 5
    assert out.splitlines()[-1] == "SUCCEEDED 1.0 5"


def test_bag_example_records_reads_and_plays(bridge: BridgeProcess, ros_node: Any,
                                             tmp_path: Path) -> None:
    """The recording example, while rclpy publishes the robot's own Status: five typed
    messages in the file, read back, then played to the robot (tests/bag checks that rclpy
    gets what is played)."""
    pub = ros_node.create_publisher(RosStatus, "/robot/status", 10)
    stop = threading.Event()

    def publish() -> None:  # the robot, at 20 Hz, until the example is done
        n = 0
        while not stop.wait(0.05):
            pub.publish(RosStatus(label=f"robot {n}"))
            n += 1

    thread = threading.Thread(target=publish, daemon=True)
    thread.start()
    try:
        code = BLOCKS["bag"].replace('"run.mcap"', repr(str(tmp_path / "run.mcap")))
        out = run_snippet(code, bridge)
    finally:
        stop.set()
        thread.join()
    lines = out.splitlines()
    assert "5 msgs" in lines[0] and "0 dropped" in lines[0], out
    assert all(line.startswith("/robot/status Status robot ") for line in lines[1:6]), out
    assert lines[6] == "5 messages"
