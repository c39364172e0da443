"""``topic bw``, ``topic delay``, ``topic find`` and ``service find`` against the real bridge,
with rclpy publishers and services on the ROS side."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from collections.abc import Iterator
from typing import Any

import pytest

from tests.cli.conftest import Run, one_error_line
from tests.cli.ros2_nodes import full_name
from tests.cli.test_commands import until_ok
from tests.helpers import ros_env

BODY = "x" * 1000
"""What the bandwidth test's publisher sends: about 1 KB of CDR."""


@pytest.fixture
def big_talker(ros_node: Any, topic: str) -> Iterator[None]:
    """An rclpy std_msgs/String publisher of :data:`BODY` on ``topic`` at 20 Hz."""
    from std_msgs.msg import String

    pub = ros_node.create_publisher(String, topic, 10)
    timer = ros_node.create_timer(0.05, lambda: pub.publish(String(data=BODY)))
    yield
    ros_node.destroy_timer(timer)
    ros_node.destroy_publisher(pub)


@pytest.fixture
def stamped_two_seconds_ago(ros_node: Any, topic: str) -> Iterator[None]:
    """An rclpy geometry_msgs/PointStamped publisher on ``topic`` at 20 Hz, each message
    stamped two seconds before it is sent."""
    from geometry_msgs.msg import PointStamped
    from rclpy.duration import Duration

    pub = ros_node.create_publisher(PointStamped, topic, 10)

    def tick() -> None:
        msg = PointStamped()
        msg.header.stamp = (ros_node.get_clock().now() - Duration(seconds=2)).to_msg()
        pub.publish(msg)

    timer = ros_node.create_timer(0.05, tick)
    yield
    ros_node.destroy_timer(timer)
    ros_node.destroy_publisher(pub)


def test_topic_bw(cli: Run, big_talker: None, topic: str) -> None:
    """topic bw prints 'Subscribed to [TOPIC]', then ros2's lines: KB/s from N messages and the
    message size as the robot serialized it (1.01 KB); --json has the exact bytes, those a
    raw rclpy subscription in another process gets (ros2 topic bw's measure)."""
    result = cli("topic", "bw", topic, "--count", "30", "--wait", "10")
    assert result.code == 0, result
    assert result.lines[0] == f"Subscribed to [{topic}]"
    rate = re.fullmatch(r"(\d+\.\d\d) KB/s from (\d+) messages", result.lines[-2])
    assert rate is not None, result.out
    assert 2.0 < float(rate[1]) < 60.0, result.out  # 20 Hz x 1.009 KB, a wide margin
    assert int(rate[2]) == 30  # the window (100) holds every message
    assert result.lines[-1] == "\tMessage size mean: 1.01 KB min: 1.01 KB max: 1.01 KB"
    size = _raw_size_elsewhere(topic)
    reports = cli("topic", "bw", topic, "--count", "3", "--json")
    assert reports.code == 0, reports
    last = json.loads(reports.lines[-1])
    assert last["min"] == last["max"] == last["mean"] == size and last["messages"] == 3


_RAW_SIZE = """
import sys, rclpy
from std_msgs.msg import String
rclpy.init()
node = rclpy.create_node("raw_size")
sizes = []
node.create_subscription(String, sys.argv[1], lambda data: sizes.append(len(data)), 10, raw=True)
while not sizes:
    rclpy.spin_once(node, timeout_sec=1.0)
print(sizes[0])
"""


def _raw_size_elsewhere(topic: str) -> int:
    """The size of a message on ``topic`` as ``ros2 topic bw`` counts it: what a raw rclpy
    subscription in a process of its own gets (DDS pads the CDR to 4 bytes between
    processes; a subscription in the publisher's process gets it unpadded)."""
    done = subprocess.run([sys.executable, "-c", _RAW_SIZE, topic], env=ros_env(),
                          capture_output=True, text=True, timeout=60, check=True)
    return int(done.stdout.split()[-1])


def test_topic_delay(cli: Run, stamped_two_seconds_ago: None, topic: str) -> None:
    """topic delay prints ros2's lines with the age of each message from its header stamp."""
    result = cli("topic", "delay", topic, "--count", "10", "--wait", "10")
    assert result.code == 0, result
    match = re.fullmatch(r"average delay: (\d+\.\d{3})", result.lines[-2])
    assert match is not None, result.out
    assert 1.9 < float(match[1]) < 4.0, result.out  # two seconds, and the trip here
    stats = re.fullmatch(r"\tmin: (\d+\.\d{3})s max: (\d+\.\d{3})s std dev: \d+\.\d{5}s "
                         r"window: (\d+)", result.lines[-1])
    assert stats is not None, result.out
    assert 1.9 < float(stats[1]) <= float(stats[2]) and stats[3] == "9"  # the first one starts


def test_topic_delay_needs_a_header(cli: Run, big_talker: None, topic: str) -> None:
    """A topic whose type has no header is refused at once, naming the topic and type."""
    one_error_line(cli("topic", "delay", topic, "--count", "1", "--wait", "10"), 2,
                   f"topic delay {topic}: its messages (std_msgs/msg/String) have no header")


def test_topic_find(cli: Run, big_talker: None, topic: str) -> None:
    """topic find TYPE lists the topics of that type (either spelling), -c counts them."""
    result = until_ok(cli, "topic", "find", "std_msgs/msg/String",
                      check=lambda r: topic in r.lines)
    assert result.lines == sorted(result.lines)
    assert topic in cli("topic", "find", "std_msgs/String").lines
    assert topic not in cli("topic", "find", "std_msgs/msg/Header").lines
    assert cli("topic", "find", "std_msgs/msg/String", "-c").lines == [str(len(result.lines))]


def test_service_find(cli: Run, ros_node: Any, topic: str) -> None:
    """service find TYPE lists the services of that type: an rclpy server, a node's
    parameter services; -c counts them."""
    from mult_msgs.srv import MultFloats

    multiplier = topic
    ros_node.create_service(MultFloats, multiplier, lambda request, response: response)
    result = until_ok(cli, "service", "find", "mult_msgs/srv/MultFloats",
                      check=lambda r: multiplier in r.lines)
    assert cli("service", "find", "mult_msgs/srv/MultFloats", "-c").lines == [
        str(len(result.lines))]
    listing = cli("service", "find", "rcl_interfaces/srv/ListParameters")
    assert f"{full_name(ros_node)}/list_parameters" in listing.lines
    assert multiplier not in listing.lines
