"""Two different stock clients on one bridge: roslibpy (PyPI) and roslib (npm) talk to each other."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from tests.peers import scenarios
from tests.peers.peer import PeerProcess


def test_roslibpy_to_roslib_topic(
    start_peer: Callable[..., PeerProcess], ros_node: Any, topic: str
) -> None:
    """A message roslibpy publishes reaches a roslib subscriber through the bridge."""
    scenarios.client_to_client_topic(start_peer("roslibpy"), start_peer("roslib"), ros_node, topic)


def test_roslib_to_roslibpy_topic(
    start_peer: Callable[..., PeerProcess], ros_node: Any, topic: str
) -> None:
    """A message roslib publishes reaches a roslibpy subscriber through the bridge."""
    scenarios.client_to_client_topic(start_peer("roslib"), start_peer("roslibpy"), ros_node, topic)


def test_roslib_serves_roslibpy(
    start_peer: Callable[..., PeerProcess], ros_node: Any, topic: str
) -> None:
    """roslibpy calls a service that roslib serves, and gets roslib's answer."""
    scenarios.client_to_client_service(start_peer("roslib"), start_peer("roslibpy"), ros_node, topic)


def test_roslibpy_serves_roslib(
    start_peer: Callable[..., PeerProcess], ros_node: Any, topic: str
) -> None:
    """roslib calls a service that roslibpy serves, and gets roslibpy's answer."""
    scenarios.client_to_client_service(start_peer("roslibpy"), start_peer("roslib"), ros_node, topic)


def test_roslib_action_serves_roslibpy(
    start_peer: Callable[..., PeerProcess], ros_node: Any, topic: str
) -> None:
    """roslibpy sends a goal to an action roslib serves, and gets roslib's result."""
    scenarios.client_to_client_action(start_peer("roslib"), start_peer("roslibpy"), ros_node, topic)


def test_latched_reaches_second_client(
    start_peer: Callable[..., PeerProcess], ros_node: Any, topic: str
) -> None:
    """A latched message reaches roslib after roslibpy, subscribed later to the same topic, got it."""
    scenarios.latched_to_second_client(start_peer("roslibpy"), start_peer("roslib"), ros_node, topic)


def test_mixed_encodings(
    start_peer: Callable[..., PeerProcess], ros_node: Any, topic: str
) -> None:
    """roslibpy (JSON) and roslib (CBOR) on one topic each get the message in their encoding."""
    scenarios.mixed_encodings(start_peer("roslibpy"), start_peer("roslib"), ros_node, topic)


def test_failing_handler_fails_other_client(
    start_peer: Callable[..., PeerProcess], ros_node: Any, topic: str
) -> None:
    """roslibpy's call to a roslib service whose handler returns false fails (not a default answer)."""
    scenarios.client_to_client_failure(start_peer("roslib"), start_peer("roslibpy"), ros_node, topic)
