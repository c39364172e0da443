"""Stock roslibpy 2.1.0 (PyPI, unchanged) against our bridge, with rclpy on the ROS side."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

from tests.peers import scenarios
from tests.peers.peer import PeerProcess


@pytest.fixture
def peer(start_peer: Callable[..., PeerProcess]) -> PeerProcess:
    """A connected roslibpy client in a child process."""
    return start_peer("roslibpy")


def test_connects_and_reports_version(peer: PeerProcess) -> None:
    """roslibpy connects to the bridge and is the pinned stock version."""
    assert peer.info["version"] == "2.1.0"
    assert peer.request("is_connected") is True


def test_publish(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslibpy publishes std_msgs/String (ROS 1 type spelling); an rclpy subscriber receives it."""
    scenarios.publish_string(peer, ros_node, topic, "std_msgs/String")


def test_publish_nested(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslibpy publishes a geometry_msgs/Twist; rclpy receives the same numbers."""
    scenarios.publish_nested(peer, ros_node, topic)


def test_subscribe(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslibpy subscribes (pkg/msg/Type spelling) and receives an rclpy publisher's message."""
    scenarios.subscribe_string(peer, ros_node, topic, "std_msgs/msg/String")


def test_subscribe_nested(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslibpy receives a CompressedImage with header stamp and base64 uint8[] data."""
    scenarios.subscribe_nested(peer, ros_node, topic)


def test_call_service(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslibpy's blocking Service.call reaches an rclpy SetBool service and returns its answer."""
    scenarios.call_setbool(peer, ros_node, topic)


def test_call_custom_service(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslibpy calls an rclpy mult_msgs/MultFloats service and gets x*y."""
    scenarios.call_mult(peer, ros_node, topic)


def test_call_missing_service(peer: PeerProcess, topic: str) -> None:
    """roslibpy's call to a service nobody offers raises ServiceException naming it, not a timeout."""
    scenarios.call_missing(peer, topic)


def test_serve_service(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslibpy serves std_srvs/SetBool; an rclpy client's calls get its answers."""
    scenarios.serve_setbool(peer, ros_node, topic)


def test_serve_custom_service(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslibpy serves mult_msgs/MultFloats; an rclpy client gets x*y."""
    scenarios.serve_mult(peer, ros_node, topic)


def test_unadvertise_service(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslibpy unadvertises its service and it leaves the ROS graph."""
    scenarios.unadvertise_service(peer, ros_node, topic)


def test_get_topics(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Ros.get_topics() lists an rclpy publisher's topic."""
    scenarios.get_topics(peer, ros_node, topic)


def test_get_topic_type(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Ros.get_topic_type() and get_topics_for_type() agree with rclpy's publisher."""
    scenarios.get_topic_type(peer, ros_node, topic)


def test_get_services(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Ros.get_services(), get_service_type() and get_services_for_type() see an rclpy service."""
    scenarios.get_services(peer, ros_node, topic)


def test_get_nodes(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Ros.get_nodes() and get_node_details() see the rclpy node and what it offers."""
    scenarios.get_nodes(peer, ros_node, topic)
