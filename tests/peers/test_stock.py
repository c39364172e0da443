"""The stock clients against our bridge, with rclpy on the ROS side: roslib 2.1.0 (npm,
unchanged, in Node) and roslibpy 2.1.0 (PyPI, unchanged), each in a child process.

Each test runs every scenario (``tests/peers/scenarios/``) against both clients (the
``kind`` parameter: ``roslibjs``, ``roslibpy``), or against the one that has the feature
(``ROSLIB_ONLY``, ``ROSLIBPY_ONLY``). The Node driver is ``tests/peers/node/peer.mjs``;
its npm packages are pinned by ``package-lock.json`` and installed by ``scripts/setup.sh``.
Node 20 has no global WebSocket unless started with ``--experimental-websocket``; roslib
then falls back to its own ``ws`` dependency. Most tests use that default path; the
``native_websocket`` ones run Node's native WebSocket. The roslibpy driver is
``tests/peers/roslibpy_peer.py``; the ``asyncio_transport`` tests run its opt-in asyncio
transport.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

from tests.peers import scenarios
from tests.peers.peer import PeerPool, PeerProcess

TRANSPORTS = {"roslib": "ws package", "roslibpy": "AutobahnRosBridgeClientFactory"}
"""Each client's default transport, as its driver reports it."""

ROSLIB_ONLY = pytest.mark.parametrize("kind", ["roslib"], ids=["roslibjs"])
"""A scenario only roslib offers (the test's ``peer`` is the roslib client)."""
ROSLIBPY_ONLY = pytest.mark.parametrize("kind", ["roslibpy"])
"""A scenario only roslibpy offers (the test's ``peer`` is the roslibpy client)."""


@pytest.fixture(params=["roslib", "roslibpy"], ids=["roslibjs", "roslibpy"])
def kind(request: pytest.FixtureRequest) -> str:
    """Which stock client: ``roslib`` (npm, in Node) or ``roslibpy`` (PyPI)."""
    return str(request.param)


@pytest.fixture
def peer(peer_pool: PeerPool, kind: str) -> PeerProcess:
    """The module's connected client of that kind (a child process), ready for this test."""
    return peer_pool.get(kind)


@pytest.fixture
def native_peer(peer_pool: PeerPool) -> PeerProcess:
    """The module's roslib client on Node's native WebSocket (--experimental-websocket)."""
    return peer_pool.get("roslib", native_websocket=True)


@pytest.fixture
def asyncio_peer(peer_pool: PeerPool) -> PeerProcess:
    """The module's roslibpy client on its opt-in asyncio transport (ROSLIBPY_TRANSPORT)."""
    return peer_pool.get("roslibpy-asyncio")


def test_connects_and_reports_version(peer: PeerProcess, kind: str) -> None:
    """Each stock client connects on its default transport (roslib: the ws package; roslibpy:
    Twisted) and is the pinned version."""
    assert peer.info["version"] == "2.1.0"
    assert peer.info["transport"] == TRANSPORTS[kind]
    assert peer.request("is_connected") is True


def test_publish(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """The client publishes std_msgs/String (ROS 1 type spelling); an rclpy subscriber receives
    it."""
    scenarios.publish_string(peer, ros_node, topic, "std_msgs/String")


def test_publish_nested(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """The client publishes a geometry_msgs/Twist (roslib: an integer where a float goes); rclpy
    gets the numbers."""
    scenarios.publish_nested(peer, ros_node, topic)


def test_subscribe(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """The client subscribes (pkg/msg/Type spelling) and receives an rclpy publisher's message."""
    scenarios.subscribe_string(peer, ros_node, topic, "std_msgs/msg/String")


def test_subscribe_nested(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """The client receives a CompressedImage with header stamp and base64 uint8[] data."""
    scenarios.subscribe_nested(peer, ros_node, topic)


def test_call_service(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """The client's service call (roslib's Service.callService, roslibpy's blocking Service.call)
    reaches an rclpy SetBool service and returns its answer."""
    scenarios.call_setbool(peer, ros_node, topic)


def test_call_custom_service(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """The client calls an rclpy mult_msgs/MultFloats service and gets x*y."""
    scenarios.call_mult(peer, ros_node, topic)


def test_call_missing_service(peer: PeerProcess, topic: str) -> None:
    """A call to a service nobody offers fails at once naming the service (roslib: its failure
    callback; roslibpy: ServiceException), not by a timeout."""
    scenarios.call_missing(peer, topic)


def test_serve_service(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """The client serves std_srvs/SetBool; an rclpy client's calls get its answers."""
    scenarios.serve_setbool(peer, ros_node, topic)


def test_serve_custom_service(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """The client serves mult_msgs/MultFloats; an rclpy client gets x*y."""
    scenarios.serve_mult(peer, ros_node, topic)


def test_unadvertise_service(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """The client unadvertises its service and it leaves the ROS graph."""
    scenarios.unadvertise_service(peer, ros_node, topic)


def test_get_topics(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Ros.getTopics() / get_topics() lists an rclpy publisher's topic with its type."""
    scenarios.get_topics(peer, ros_node, topic)


def test_get_topic_type(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Ros.getTopicType() / get_topic_type() and getTopicsForType() / get_topics_for_type() agree
    with rclpy's publisher."""
    scenarios.get_topic_type(peer, ros_node, topic)


def test_get_services(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Ros.getServices() / get_services(), the service type and the services for a type see an rclpy
    service."""
    scenarios.get_services(peer, ros_node, topic)


def test_get_nodes(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Ros.getNodes() / get_nodes() and the node details see the rclpy node and what it offers."""
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
    """A late the client subscription gets the last message of a transient-local rclpy publisher."""
    scenarios.subscribe_latched(peer, ros_node, topic)


def test_bad_type_then_publish(peer: PeerProcess, kind: str, ros_node: Any, topic: str) -> None:
    """After the bridge refuses an unknown message type the connection still publishes; roslib also
    gets the error status naming the type."""
    scenarios.bad_type_then_publish(peer, ros_node, topic, sees_status=kind == "roslib")


@ROSLIB_ONLY
def test_subscribe_cbor(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """compression "cbor": roslib decodes float64[] typed arrays and the rest of a JointState."""
    scenarios.subscribe_cbor(peer, ros_node, topic)


@ROSLIB_ONLY
@pytest.mark.parametrize(("type_name", "values", "typed"), scenarios.CBOR_ARRAYS)
def test_subscribe_cbor_typed_arrays(
    peer: PeerProcess, ros_node: Any, topic: str, type_name: str, values: list[Any], typed: str
) -> None:
    """compression "cbor": each numeric array type decodes to its JavaScript typed array."""
    scenarios.subscribe_cbor_typed_array(peer, ros_node, topic, type_name, values, typed)


@ROSLIB_ONLY
def test_subscribe_cbor_bytes(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """compression "cbor": roslib gets a uint8[] field as the same bytes in a Uint8Array."""
    scenarios.subscribe_cbor_bytes(peer, ros_node, topic)


@ROSLIB_ONLY
def test_subscribe_cbor_raw(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """compression "cbor-raw": roslib gets CDR bytes that rclpy deserializes to the same message."""
    scenarios.subscribe_cbor_raw(peer, ros_node, topic)


def test_params(peer: PeerProcess, ros_node: Any) -> None:
    """Ros.getParams() / get_params() and the parameter get and set reach an rclpy node's
    parameter."""
    scenarios.params(peer, ros_node)


def test_message_details(peer: PeerProcess) -> None:
    """Ros.getMessageDetails() / get_message_details() returns rosapi typedefs for a nested type
    (roslib decodes them with Ros.decodeTypeDefs())."""
    scenarios.message_details(peer)


def test_service_details(peer: PeerProcess) -> None:
    """The service request and response details (getServiceRequestDetails() /
    get_service_request_details(), ...) return typedefs."""
    scenarios.service_details(peer)


@ROSLIB_ONLY
def test_topics_and_raw_types(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Ros.getTopicsAndRawTypes() lists the topic with its type and definition text."""
    scenarios.topics_and_raw_types(peer, ros_node, topic)


def test_send_action_goal(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A goal (ROSLIB.Action.sendGoal, roslibpy.ActionClient) reaches an rclpy action server and
    gets the result."""
    scenarios.send_goal(peer, ros_node, topic)


def test_cancel_action_goal(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Canceling a goal after its first feedback cancels the rclpy goal, and the client hears it."""
    scenarios.cancel_goal(peer, ros_node, topic)


@ROSLIB_ONLY
def test_serve_action(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """ROSLIB.Action.advertise serves Fibonacci; an rclpy ActionClient gets the result."""
    scenarios.serve_action(peer, ros_node, topic)


@ROSLIB_ONLY
def test_serve_action_canceled(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """An rclpy cancel reaches roslib's Action cancel callback; its setCanceled ends the goal."""
    scenarios.serve_action_canceled(peer, ros_node, topic)


def test_burst_in_order(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """100 messages the client publishes back to back all reach rclpy, in order."""
    scenarios.burst_in_order(peer, ros_node, topic)


def test_failing_handler(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A service handler returning false still gets the rclpy caller an answer."""
    scenarios.failing_handler(peer, ros_node, topic)


@ROSLIB_ONLY
def test_call_timeout(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """callService's timeout argument makes a too-slow rclpy service fail promptly."""
    scenarios.call_timeout(peer, ros_node, topic)


def test_publish_large(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """The client publishes a 1.5 MB Image; rclpy gets every byte."""
    scenarios.publish_large(peer, ros_node, topic)


def test_subscribe_large(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """The client receives a 1.5 MB Image from rclpy with every byte."""
    scenarios.subscribe_large(peer, ros_node, topic)


def test_killed_client_service_goes(
    start_peer: Callable[..., PeerProcess], kind: str, ros_node: Any, topic: str
) -> None:
    """Killing a client's process that serves a service removes the service from the graph."""
    scenarios.killed_client_service_goes(start_peer(kind), ros_node, topic)


def test_two_subscriptions(peer: PeerProcess, kind: str, ros_node: Any, topic: str) -> None:
    """Two Topics of one client on one topic each get every message once; with roslib either can
    unsubscribe alone."""
    scenarios.two_subscriptions(peer, ros_node, topic, unsubscribe_one=kind == "roslib")


def test_subscription_options(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A subscription with throttle_rate and queue_length still delivers."""
    scenarios.subscription_options(peer, ros_node, topic)


def test_call_bad_args(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A call with a bad value or unknown field fails naming the field."""
    scenarios.call_bad_args(peer, ros_node, topic)


@ROSLIB_ONLY
def test_subscribe_png_compression(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A roslib Topic with compression "png" still receives messages."""
    scenarios.subscribe_png(peer, ros_node, topic)


@ROSLIB_ONLY
def test_bad_fields_named(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslib gets error statuses naming an unknown field and a mistyped one; publishing goes on."""
    scenarios.bad_fields_named(peer, ros_node, topic)


@ROSLIB_ONLY
def test_subscribe_wrong_type(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslib subscribing with the wrong type gets an error status naming both types."""
    scenarios.subscribe_wrong_type(peer, ros_node, topic)


def test_get_action_servers(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Ros.getActionServers() names an rclpy action server."""
    scenarios.get_action_servers(peer, ros_node, topic)


@ROSLIB_ONLY
def test_get_publishers(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Topic.getPublishers() names the rclpy node publishing the topic."""
    scenarios.get_publishers(peer, ros_node, topic)


@ROSLIB_ONLY
def test_serve_async(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """Service.advertiseAsync serves mult_msgs/MultFloats to an rclpy client."""
    scenarios.serve_async(peer, ros_node, topic)


def test_non_finite_floats(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """The client receives NaN and infinities as null / None (roslib's JSON.parse has no NaN),
    finite values intact."""
    scenarios.non_finite_floats(peer, ros_node, topic)


def test_subscribe_best_effort_publisher_first(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """The client hears a best-effort (sensor QoS) rclpy publisher that existed before it
    subscribed."""
    scenarios.subscribe_best_effort(peer, ros_node, topic, publisher_first=True)


def test_subscribe_best_effort_publisher_later(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """The client hears a best-effort (sensor QoS) rclpy publisher that appeared after it
    subscribed."""
    scenarios.subscribe_best_effort(peer, ros_node, topic, publisher_first=False)


def test_concurrent_calls(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A call completes while another call on the same connection waits on a slow service."""
    scenarios.concurrent_calls(peer, ros_node, topic)


def test_subscribe_without_type(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A Topic created without a message type subscribes with the topic's graph type."""
    scenarios.subscribe_without_type(peer, ros_node, topic)


def test_hears_itself(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A client subscribed to the topic it publishes receives its own messages."""
    scenarios.hears_itself(peer, ros_node, topic)


def test_relative_names(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """The client topics named without the leading slash reach the absolute ROS topics, both
    ways."""
    scenarios.relative_names(peer, ros_node, topic)


def test_serve_relative_name(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A service advertised without the leading slash answers an rclpy caller."""
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


@ROSLIBPY_ONLY
def test_publish_ros2_header_helper(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """A PoseStamped built with roslibpy.ros2.Header (secs/nsecs stamp) reaches rclpy with its time."""
    scenarios.publish_ros1_time_keys(peer, ros_node, topic)


@ROSLIBPY_ONLY
def test_get_time(peer: PeerProcess) -> None:
    """Ros.get_time() gets the bridge clock in the secs/nsecs shape roslibpy reads."""
    scenarios.get_time(peer)


@ROSLIBPY_ONLY
def test_big_integers(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """roslibpy receives int64/uint64 extremes exactly."""
    scenarios.big_integers(peer, ros_node, topic)


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
