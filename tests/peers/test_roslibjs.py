"""Stock roslib 2.1.0 (npm, unchanged) in Node against our bridge, with rclpy on the ROS side.

The Node driver is ``tests/peers/node/peer.mjs``; its npm packages are pinned
by ``package-lock.json`` and installed by ``scripts/setup.sh``. Node 20 has no
global WebSocket unless started with ``--experimental-websocket``; roslib then
falls back to its own ``ws`` dependency. Most tests use that default path; the
last ones run Node's native WebSocket too.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

from tests.peers import scenarios
from tests.peers.peer import PeerPool, PeerProcess


@pytest.fixture
def peer(peer_pool: PeerPool) -> PeerProcess:
    """The module's connected roslib client (ws package, in Node), ready for this test."""
    return peer_pool.get("roslib")


@pytest.fixture
def native_peer(peer_pool: PeerPool) -> PeerProcess:
    """The module's roslib client on Node's native WebSocket (--experimental-websocket)."""
    return peer_pool.get("roslib", native_websocket=True)


def test_connects_and_reports_version(peer: PeerProcess) -> None:
    """roslib connects through the ws package and is the pinned stock version."""
    assert peer.info["version"] == "2.1.0"
    assert peer.info["transport"] == "ws package"
    assert peer.request("is_connected") is True


def test_publish(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslib publishes std_msgs/String (ROS 1 type spelling); an rclpy subscriber receives it."""
    scenarios.publish_string(peer, ros_node, topic, "std_msgs/String")


def test_publish_nested(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslib publishes a geometry_msgs/Twist (an integer where a float goes); rclpy gets the numbers."""
    scenarios.publish_nested(peer, ros_node, topic)


def test_subscribe(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslib subscribes (pkg/msg/Type spelling) and receives an rclpy publisher's message."""
    scenarios.subscribe_string(peer, ros_node, topic, "std_msgs/msg/String")


def test_subscribe_nested(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslib receives a CompressedImage with header stamp and base64 uint8[] data."""
    scenarios.subscribe_nested(peer, ros_node, topic)


def test_call_service(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslib's Service.callService reaches an rclpy SetBool service and returns its answer."""
    scenarios.call_setbool(peer, ros_node, topic)


def test_call_custom_service(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslib calls an rclpy mult_msgs/MultFloats service and gets x*y."""
    scenarios.call_mult(peer, ros_node, topic)


def test_call_missing_service(peer: PeerProcess, topic: str) -> None:
    """roslib's call to a service nobody offers reaches its failure callback, naming the service."""
    scenarios.call_missing(peer, topic)


def test_serve_service(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslib serves std_srvs/SetBool; an rclpy client's calls get its answers."""
    scenarios.serve_setbool(peer, ros_node, topic)


def test_serve_custom_service(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslib serves mult_msgs/MultFloats; an rclpy client gets x*y."""
    scenarios.serve_mult(peer, ros_node, topic)


def test_unadvertise_service(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslib unadvertises its service and it leaves the ROS graph."""
    scenarios.unadvertise_service(peer, ros_node, topic)


def test_get_topics(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Ros.getTopics() (service name without leading slash) lists the topic with its type."""
    scenarios.get_topics(peer, ros_node, topic)


def test_get_topic_type(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Ros.getTopicType() and getTopicsForType() agree with rclpy's publisher."""
    scenarios.get_topic_type(peer, ros_node, topic)


def test_get_services(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Ros.getServices(), getServiceType() and getServicesForType() see an rclpy service."""
    scenarios.get_services(peer, ros_node, topic)


def test_get_nodes(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Ros.getNodes() and getNodeDetails() see the rclpy node and what it offers."""
    scenarios.get_nodes(peer, ros_node, topic)


def test_unsubscribe(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Topic.unsubscribe() makes the bridge drop its ROS subscription."""
    scenarios.unsubscribe(peer, ros_node, topic)


def test_unadvertise(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Topic.unadvertise() makes the bridge's ROS publisher leave the graph."""
    scenarios.unadvertise(peer, ros_node, topic)


def test_publish_latched(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A latched Topic's message reaches a transient-local rclpy subscriber that joins later."""
    scenarios.publish_latched(peer, ros_node, topic)


def test_subscribe_latched(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A late roslib subscription gets the last message of a transient-local rclpy publisher."""
    scenarios.subscribe_latched(peer, ros_node, topic)


def test_bad_type_then_publish(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslib gets an error status naming an unknown type, and the connection still publishes."""
    scenarios.bad_type_then_publish(peer, ros_node, topic, sees_status=True)


def test_subscribe_cbor(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """compression "cbor": roslib decodes float64[] typed arrays and the rest of a JointState."""
    scenarios.subscribe_cbor(peer, ros_node, topic)


@pytest.mark.parametrize(("type_name", "values", "typed"), scenarios.CBOR_ARRAYS)
def test_subscribe_cbor_typed_arrays(
    peer: PeerProcess, ros_node: Any, topic: str, type_name: str, values: list[Any], typed: str
) -> None:
    """compression "cbor": each numeric array type decodes to its JavaScript typed array."""
    scenarios.subscribe_cbor_typed_array(peer, ros_node, topic, type_name, values, typed)


def test_subscribe_cbor_bytes(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """compression "cbor": roslib gets a uint8[] field as the same bytes in a Uint8Array."""
    scenarios.subscribe_cbor_bytes(peer, ros_node, topic)


def test_subscribe_cbor_raw(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """compression "cbor-raw": roslib gets CDR bytes that rclpy deserializes to the same message."""
    scenarios.subscribe_cbor_raw(peer, ros_node, topic)


def test_params(peer: PeerProcess, ros_node: Any) -> None:
    """Ros.getParams() and ROSLIB.Param get/set reach an rclpy node's parameter."""
    scenarios.params(peer, ros_node)


def test_message_details(peer: PeerProcess) -> None:
    """Ros.getMessageDetails() typedefs for a nested type decode with Ros.decodeTypeDefs()."""
    scenarios.message_details(peer)


def test_service_details(peer: PeerProcess) -> None:
    """Ros.getServiceRequestDetails()/getServiceResponseDetails() return typedefs."""
    scenarios.service_details(peer)


def test_topics_and_raw_types(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Ros.getTopicsAndRawTypes() lists the topic with its type and definition text."""
    scenarios.topics_and_raw_types(peer, ros_node, topic)


def test_send_action_goal(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """ROSLIB.Action.sendGoal reaches an rclpy action server and gets the result."""
    scenarios.send_goal(peer, ros_node, topic)


def test_cancel_action_goal(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Action.cancelGoal after the first feedback cancels the rclpy goal; roslib reports it."""
    scenarios.cancel_goal(peer, ros_node, topic)


def test_serve_action(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """ROSLIB.Action.advertise serves Fibonacci; an rclpy ActionClient gets the result."""
    scenarios.serve_action(peer, ros_node, topic)


def test_serve_action_canceled(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """An rclpy cancel reaches roslib's Action cancel callback; its setCanceled ends the goal."""
    scenarios.serve_action_canceled(peer, ros_node, topic)


def test_burst_in_order(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """100 messages roslib publishes back to back all reach rclpy, in order."""
    scenarios.burst_in_order(peer, ros_node, topic)


def test_failing_handler(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A roslib service handler returning false still gets the rclpy caller an answer."""
    scenarios.failing_handler(peer, ros_node, topic)


def test_call_timeout(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """callService's timeout argument makes a too-slow rclpy service fail promptly."""
    scenarios.call_timeout(peer, ros_node, topic)


def test_publish_large(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslib publishes a 1.5 MB Image; rclpy gets every byte."""
    scenarios.publish_large(peer, ros_node, topic)


def test_subscribe_large(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslib receives a 1.5 MB Image from rclpy with every byte."""
    scenarios.subscribe_large(peer, ros_node, topic)


def test_killed_client_service_goes(
    start_peer: Callable[..., PeerProcess], ros_node: Any, topic: str
) -> None:
    """Killing a Node process that serves a service removes the service from the graph."""
    scenarios.killed_client_service_goes(start_peer("roslib"), ros_node, topic)


def test_two_subscriptions(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Two roslib Topics on one topic each get every message once; either can unsubscribe alone."""
    scenarios.two_subscriptions(peer, ros_node, topic)


def test_subscription_options(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A roslib subscription with throttle_rate and queue_length still delivers."""
    scenarios.subscription_options(peer, ros_node, topic)


def test_call_bad_args(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A roslib call with a bad value or unknown field fails naming the field."""
    scenarios.call_bad_args(peer, ros_node, topic)


def test_subscribe_png_compression(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A roslib Topic with compression "png" still receives messages."""
    scenarios.subscribe_png(peer, ros_node, topic)


def test_bad_fields_named(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslib gets error statuses naming an unknown field and a mistyped one; publishing goes on."""
    scenarios.bad_fields_named(peer, ros_node, topic)


def test_subscribe_wrong_type(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslib subscribing with the wrong type gets an error status naming both types."""
    scenarios.subscribe_wrong_type(peer, ros_node, topic)


def test_get_action_servers(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Ros.getActionServers() names an rclpy action server."""
    scenarios.get_action_servers(peer, ros_node, topic)


def test_get_publishers(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Topic.getPublishers() names the rclpy node publishing the topic."""
    scenarios.get_publishers(peer, ros_node, topic)


def test_serve_async(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Service.advertiseAsync serves mult_msgs/MultFloats to an rclpy client."""
    scenarios.serve_async(peer, ros_node, topic)


def test_non_finite_floats(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslib (JSON.parse, which has no NaN) receives NaN and infinities as null."""
    scenarios.non_finite_floats(peer, ros_node, topic)


def test_subscribe_best_effort_publisher_first(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslib hears a best-effort (sensor QoS) rclpy publisher that existed before it subscribed."""
    scenarios.subscribe_best_effort(peer, ros_node, topic, publisher_first=True)


def test_subscribe_best_effort_publisher_later(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslib hears a best-effort (sensor QoS) rclpy publisher that appeared after it subscribed."""
    scenarios.subscribe_best_effort(peer, ros_node, topic, publisher_first=False)


def test_concurrent_calls(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A roslib call completes while another call on the same connection waits on a slow service."""
    scenarios.concurrent_calls(peer, ros_node, topic)


def test_subscribe_without_type(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A roslib Topic created without a message type subscribes with the topic's graph type."""
    scenarios.subscribe_without_type(peer, ros_node, topic)


def test_hears_itself(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A roslib client subscribed to the topic it publishes receives its own messages."""
    scenarios.hears_itself(peer, ros_node, topic)


def test_relative_names(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslib topics named without the leading slash reach the absolute ROS topics, both ways."""
    scenarios.relative_names(peer, ros_node, topic)


def test_serve_relative_name(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A roslib service advertised without the leading slash answers an rclpy caller."""
    scenarios.serve_relative_name(peer, ros_node, topic)


def test_native_websocket_publish(native_peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """With Node's native WebSocket, roslib's published message reaches rclpy."""
    assert native_peer.info["transport"] == "native WebSocket"
    scenarios.publish_string(native_peer, ros_node, topic, "std_msgs/msg/String")


def test_native_websocket_subscribe(native_peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """With Node's native WebSocket, roslib receives an rclpy publisher's message."""
    scenarios.subscribe_string(native_peer, ros_node, topic, "std_msgs/String")


def test_native_websocket_call_service(native_peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """With Node's native WebSocket, roslib calls an rclpy service and gets its answer."""
    scenarios.call_setbool(native_peer, ros_node, topic)
