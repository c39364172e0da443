"""examples/multi_robot.py against two real bridges (two robots) and an rclpy node."""

from __future__ import annotations

import sys
from typing import Any

from tests.examples.support import Program
from tests.helpers import BridgeProcess, wait_until


def test_multi_robot_talks_to_two_bridges_at_once(
    make_bridge: Any, ros_node: Any, topic: str
) -> None:
    """The program connects to both bridges, commands each robot once and hears each one."""
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from std_msgs.msg import String

    alpha: BridgeProcess = make_bridge()
    beta: BridgeProcess = make_bridge()
    commands: list[str] = []
    latched = QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL)  # type: ignore[no-untyped-call]
    ros_node.create_subscription(String, topic + "_cmd", lambda m: commands.append(m.data),
                                 latched)
    pub = ros_node.create_publisher(String, topic, 10)
    ros_node.create_timer(1 / 20, lambda: pub.publish(String(data="all good")))
    app = Program([sys.executable, "-m", "examples.multi_robot",
                   "--robot", f"alpha={alpha.url}", "--robot", f"beta={beta.url}",
                   "--topic", topic, "--command-topic", topic + "_cmd",
                   "--command", "dock", "--count", "3"])
    try:
        for name, b in (("alpha", alpha), ("beta", beta)):
            app.wait_for(rf"^\[{name}\] connected to {b.url}: ROS 2 jazzy, \d+ topics$")
        for name in ("alpha", "beta"):
            app.wait_for(rf"^\[{name}\] {topic}: all good$", timeout=20)
        assert app.proc.wait(30) == 0, app.dump()
        assert sum(line.startswith("[alpha] " + topic) for line in app.out) == 3
        assert sum(line.startswith("[beta] " + topic) for line in app.out) == 3
        # Both robots got the command, each through its own bridge.
        wait_until(lambda: len(commands) >= 2, 15, "both commands")
        assert sorted(commands) == ["dock (to alpha)", "dock (to beta)"]
    finally:
        app.kill()
