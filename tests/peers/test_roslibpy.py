"""Stock roslibpy 2.1.0 (PyPI, unchanged) against our bridge, with rclpy on the ROS side."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

from tests.peers import scenarios
from tests.peers.peer import PeerPool, PeerProcess


@pytest.fixture
def peer(peer_pool: PeerPool) -> PeerProcess:
    """The module's connected roslibpy client (a child process), ready for this test."""
    return peer_pool.get("roslibpy")


@pytest.fixture
def asyncio_peer(peer_pool: PeerPool) -> PeerProcess:
    """The module's roslibpy client on its opt-in asyncio transport (ROSLIBPY_TRANSPORT)."""
    return peer_pool.get("roslibpy-asyncio")


def test_connects_and_reports_version(peer: PeerProcess) -> None:
    """roslibpy connects (default Twisted transport) and is the pinned stock version."""
    assert peer.info["version"] == "2.1.0"
    assert peer.info["transport"] == "AutobahnRosBridgeClientFactory"
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
    """Ros.get_topics() lists an rclpy publisher's topic; get_topic_type() gives its type."""
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


def test_unsubscribe(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Topic.unsubscribe() makes the bridge drop its ROS subscription."""
    scenarios.unsubscribe(peer, ros_node, topic)


def test_unadvertise(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Topic.unadvertise() makes the bridge's ROS publisher leave the graph."""
    scenarios.unadvertise(peer, ros_node, topic)


def test_publish_latched(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A Topic(latch=True) message reaches a transient-local rclpy subscriber that joins later."""
    scenarios.publish_latched(peer, ros_node, topic)


def test_subscribe_latched(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A late roslibpy subscription gets the last message of a transient-local rclpy publisher."""
    scenarios.subscribe_latched(peer, ros_node, topic)


def test_bad_type_then_publish(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """After the bridge refuses an unknown message type, the connection still publishes."""
    scenarios.bad_type_then_publish(peer, ros_node, topic, sees_status=False)


def test_params(peer: PeerProcess, ros_node: Any) -> None:
    """Ros.get_params(), get_param() and set_param() reach an rclpy node's parameter."""
    scenarios.params(peer, ros_node)


def test_message_details(peer: PeerProcess) -> None:
    """Ros.get_message_details() returns rosapi typedefs for a nested message type."""
    scenarios.message_details(peer)


def test_service_details(peer: PeerProcess) -> None:
    """Ros.get_service_request_details()/get_service_response_details() return typedefs."""
    scenarios.service_details(peer)


def test_send_action_goal(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslibpy.ActionClient sends a goal to an rclpy action server and gets the result."""
    scenarios.send_goal(peer, ros_node, topic)


def test_cancel_action_goal(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """ActionClient.cancel_goal after the first feedback cancels the rclpy goal; errback hears it."""
    scenarios.cancel_goal(peer, ros_node, topic)


def test_publish_ros2_header_helper(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A PoseStamped built with roslibpy.ros2.Header (secs/nsecs stamp) reaches rclpy with its time."""
    scenarios.publish_ros1_time_keys(peer, ros_node, topic)


def test_burst_in_order(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """100 messages roslibpy publishes back to back all reach rclpy, in order."""
    scenarios.burst_in_order(peer, ros_node, topic)


def test_failing_handler(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A roslibpy service handler returning False still gets the rclpy caller an answer."""
    scenarios.failing_handler(peer, ros_node, topic)


def test_publish_large(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslibpy publishes a 1.5 MB Image; rclpy gets every byte."""
    scenarios.publish_large(peer, ros_node, topic)


def test_subscribe_large(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslibpy receives a 1.5 MB Image from rclpy with every byte."""
    scenarios.subscribe_large(peer, ros_node, topic)


def test_killed_client_service_goes(
    start_peer: Callable[..., PeerProcess], ros_node: Any, topic: str
) -> None:
    """Killing a roslibpy process that serves a service removes the service from the graph."""
    scenarios.killed_client_service_goes(start_peer("roslibpy"), ros_node, topic)


def test_two_subscriptions(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Two roslibpy Topics on one topic (two subscribe ids) each get every message once."""
    scenarios.two_subscriptions(peer, ros_node, topic, unsubscribe_one=False)


def test_subscription_options(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A roslibpy subscription with throttle_rate and queue_length still delivers."""
    scenarios.subscription_options(peer, ros_node, topic)


def test_call_bad_args(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A roslibpy call with a bad value or unknown field fails naming the field."""
    scenarios.call_bad_args(peer, ros_node, topic)


def test_get_action_servers(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Ros.get_action_servers() names an rclpy action server."""
    scenarios.get_action_servers(peer, ros_node, topic)


def test_get_time(peer: PeerProcess) -> None:
    """Ros.get_time() gets the bridge clock in the secs/nsecs shape roslibpy reads."""
    scenarios.get_time(peer)


def test_non_finite_floats(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslibpy receives NaN and infinities as None, finite values intact."""
    scenarios.non_finite_floats(peer, ros_node, topic)


def test_big_integers(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslibpy receives int64/uint64 extremes exactly."""
    scenarios.big_integers(peer, ros_node, topic)


def test_subscribe_best_effort_publisher_first(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslibpy hears a best-effort (sensor QoS) rclpy publisher that existed before it subscribed."""
    scenarios.subscribe_best_effort(peer, ros_node, topic, publisher_first=True)


def test_subscribe_best_effort_publisher_later(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslibpy hears a best-effort (sensor QoS) rclpy publisher that appeared after it subscribed."""
    scenarios.subscribe_best_effort(peer, ros_node, topic, publisher_first=False)


def test_concurrent_calls(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A roslibpy call completes while another call on the same connection waits on a slow service."""
    scenarios.concurrent_calls(peer, ros_node, topic)


def test_asyncio_transport_publish(asyncio_peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """On roslibpy's asyncio transport, a published message reaches rclpy."""
    assert asyncio_peer.info["transport"] != "AutobahnRosBridgeClientFactory"
    scenarios.publish_string(asyncio_peer, ros_node, topic, "std_msgs/msg/String")


def test_asyncio_transport_subscribe(asyncio_peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """On roslibpy's asyncio transport, an rclpy publisher's message arrives."""
    scenarios.subscribe_string(asyncio_peer, ros_node, topic, "std_msgs/String")


def test_asyncio_transport_call_service(
    asyncio_peer: PeerProcess, ros_node: Any, topic: str
) -> None:
    """On roslibpy's asyncio transport, a blocking Service.call gets the rclpy service's answer."""
    scenarios.call_setbool(asyncio_peer, ros_node, topic)


def test_asyncio_transport_serve_service(
    asyncio_peer: PeerProcess, ros_node: Any, topic: str
) -> None:
    """On roslibpy's asyncio transport, a served service answers an rclpy client."""
    scenarios.serve_setbool(asyncio_peer, ros_node, topic)


def test_asyncio_transport_send_action_goal(
    asyncio_peer: PeerProcess, ros_node: Any, topic: str
) -> None:
    """On roslibpy's asyncio transport, an action goal gets the rclpy server's feedback and result."""
    scenarios.send_goal(asyncio_peer, ros_node, topic)


def test_asyncio_transport_cancel_action_goal(
    asyncio_peer: PeerProcess, ros_node: Any, topic: str
) -> None:
    """On roslibpy's asyncio transport, canceling a goal after its first feedback cancels it."""
    scenarios.cancel_goal(asyncio_peer, ros_node, topic)


def test_reconnect_after_bridge_restart(
    make_bridge: Callable[..., Any], ros_node: Any, topic: str
) -> None:
    """roslibpy reconnects by itself to a restarted bridge; its subscription and service come back."""
    private = make_bridge()
    pool = PeerPool(private)
    try:
        scenarios.reconnect_after_bridge_restart(pool.get("roslibpy"), private, ros_node, topic)
    finally:
        pool.close()


def test_subscribe_without_type(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A roslibpy Topic created without a message type subscribes with the topic's graph type."""
    scenarios.subscribe_without_type(peer, ros_node, topic)


def test_hears_itself(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A roslibpy client subscribed to the topic it publishes receives its own messages."""
    scenarios.hears_itself(peer, ros_node, topic)


def test_relative_names(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslibpy topics named without the leading slash reach the absolute ROS topics, both ways."""
    scenarios.relative_names(peer, ros_node, topic)


def test_serve_relative_name(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A roslibpy service advertised without the leading slash answers an rclpy caller."""
    scenarios.serve_relative_name(peer, ros_node, topic)
