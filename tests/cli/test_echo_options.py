"""topic echo --once and --field, as ros2 users type them by habit."""

from __future__ import annotations

import re
from collections.abc import Iterator
from typing import Any

import pytest

from tests.cli.conftest import Run


@pytest.fixture
def pose_talker(ros_node: Any, topic: str) -> Iterator[None]:
    """An rclpy publisher of geometry_msgs/Pose with position.x = 1.5 on ``topic`` at 20 Hz."""
    from geometry_msgs.msg import Pose

    pub = ros_node.create_publisher(Pose, topic, 10)
    msg = Pose()
    msg.position.x = 1.5
    timer = ros_node.create_timer(0.05, lambda: pub.publish(msg))
    yield
    ros_node.destroy_timer(timer)
    ros_node.destroy_publisher(pub)


def test_echo_once_prints_one_message(cli: Run, pose_talker: None, topic: str) -> None:
    """--once prints exactly one YAML document and exits 0."""
    result = cli("topic", "echo", topic, "--once", "--wait", "10")
    assert result.code == 0, result
    docs = result.out.split("---\n")
    assert len(docs) == 2 and docs[1] == ""
    assert "position:" in docs[0]


def test_echo_field_prints_the_nested_field(cli: Run, pose_talker: None, topic: str) -> None:
    """--field position.x prints only that value; --field position the nested message."""
    result = cli("topic", "echo", topic, "--once", "--field", "position.x", "--wait", "10")
    assert (result.code, result.out) == (0, "1.5\n---\n"), result
    nested = cli("topic", "echo", topic, "geometry_msgs/msg/Pose", "--once", "--json",
                 "--field", "position")
    assert nested.code == 0 and nested.lines == ['{"x":1.5,"y":0.0,"z":0.0}'], nested


def test_echo_field_that_does_not_exist_names_the_fields(
    cli: Run, pose_talker: None, topic: str
) -> None:
    """A wrong --field fails with a usage error listing the fields there are."""
    result = cli("topic", "echo", topic, "geometry_msgs/msg/Pose", "--once",
                 "--field", "position.w")
    assert result.code != 0
    assert re.search(r"position has no field 'w' \(fields: x, y, z\)", result.err), result
