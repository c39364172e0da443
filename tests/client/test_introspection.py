"""``ros.graph`` sees rclpy's nodes through the bridge: their topics, services, actions and
parameters, with the types ROS gives them; the blocking client's ``graph`` says the same."""

from __future__ import annotations

from typing import Any

import pytest
from rclpy.action.server import ActionServer
from std_msgs.msg import Int32, String
from std_srvs.srv import SetBool
from test_msgs.action import Fibonacci

from roslibpy_lite import Client, sync
from roslibpy_lite.capabilities.introspection import (
    GraphAction,
    GraphNode,
    GraphService,
    GraphTopic,
)
from tests.conformance.test_introspection import until
from tests.helpers import BridgeProcess, wait_until


@pytest.fixture
def rclpy_robot(ros_node: Any, topic: str) -> Any:
    """An rclpy node with a publisher, a subscription, a service, an action and a parameter."""
    ros_node.create_publisher(String, topic + "_chatter", 10)
    ros_node.create_subscription(Int32, topic + "_cmd", lambda msg: None, 10)
    ros_node.create_service(SetBool, topic + "_enable", lambda req, res: res)
    ros_node.robot_action = ActionServer(  # type: ignore[no-untyped-call]
        ros_node, Fibonacci, topic + "_fib", lambda handle: Fibonacci.Result())
    ros_node.declare_parameter("gain", 0.5)
    return ros_node


async def test_rclpy_node_seen_whole(client: Client, rclpy_robot: Any, topic: str) -> None:
    """An rclpy node's publisher, subscription, service, action and parameter, with types."""
    fq = str(rclpy_robot.get_fully_qualified_name())

    async def robot() -> GraphNode | None:
        return next((n for n in await client.graph.nodes() if n.name == fq), None)

    node = await until(robot, lambda n: n is not None and topic + "_enable" in n.services
                       and topic + "_chatter" in n.publishers and topic + "_cmd" in n.subscribers)
    assert node is not None
    assert isinstance(node, GraphNode) and node.name == fq
    topics = await client.graph.topics()
    assert GraphTopic(topic + "_chatter", "std_msgs/msg/String") in topics
    assert GraphTopic(topic + "_cmd", "std_msgs/msg/Int32") in topics
    assert GraphService(topic + "_enable", "std_srvs/srv/SetBool") in await client.graph.services()
    actions = await until(client.graph.actions, lambda a: topic + "_fib" in {x.name for x in a})
    assert GraphAction(topic + "_fib", "test_msgs/action/Fibonacci") in actions
    assert node in await client.graph.nodes()
    await until(client.graph.params, lambda names: f"{fq}:gain" in names, timeout=30)
    await client.graph.set_param(f"{fq}:gain", 0.75)
    assert rclpy_robot.get_parameter("gain").value == 0.75


def test_blocking_graph(bridge: BridgeProcess, rclpy_robot: Any, topic: str) -> None:
    """The blocking client's ``graph`` gives the same values, without await."""
    fq = str(rclpy_robot.get_fully_qualified_name())
    with sync.connect(bridge.url) as ros:
        wait_until(lambda: fq in ros.graph.node_names(), 15, "the node")
        wait_until(lambda: topic + "_enable" in ros.graph.node(fq).services, 15, "the service")
        assert ros.graph.topic_type(topic + "_chatter") == "std_msgs/msg/String"
        assert ros.graph.service_type(topic + "_enable") == "std_srvs/srv/SetBool"
        assert GraphService(topic + "_enable", "std_srvs/srv/SetBool") in ros.graph.services()
        assert fq in ros.graph.node_names()
        wait_until(lambda: f"{fq}:gain" in ros.graph.params(), 30, "the parameter")
        assert ros.graph.get_param(f"{fq}:gain") == 0.5
        ros.graph.set_param(f"{fq}:gain", 2.0)
        assert rclpy_robot.get_parameter("gain").value == 2.0
        assert ros.graph.has_param(f"{fq}:gain")


def test_blocking_graph_on_mock() -> None:
    """sync.MockRos's ``graph`` answers from what it holds, as the asyncio mock's."""
    with sync.MockRos() as ros:
        ros.advertise("/out", "std_msgs/msg/String")
        ros.add_node("/n", {})
        ros.graph.set_param("/n:gain", 1)
        assert ros.graph.topics() == [GraphTopic("/out", "std_msgs/msg/String")]
        assert ros.graph.get_param("/n:gain") == 1
        assert "/n" in ros.graph.node_names()
        assert ros.graph.node("/roslibpy_lite_mock").publishers == ("/out",)
        assert ros.graph.actions() == []
        ros.graph.delete_param("/n:gain")
        assert not ros.graph.has_param("/n:gain")


def test_params_skip_a_node_without_parameter_services(
        bridge: BridgeProcess, ros_runtime: Any, rclpy_robot: Any, topic: str) -> None:
    """A node started without parameter services is skipped at once, so a warm params()
    answers within a timeout shorter than the bridge's wait for a node's parameter service
    (PARAM_TIMEOUT, 2 s); params(node) gives one node's parameters with their values."""
    quiet = ros_runtime.rclpy.create_node(topic.strip("/") + "_quiet", context=ros_runtime.context,
                                          start_parameter_services=False)
    fq = str(rclpy_robot.get_fully_qualified_name())
    try:
        with sync.connect(bridge.url) as ros:
            wait_until(lambda: quiet.get_fully_qualified_name() in ros.graph.node_names(), 15,
                       "the quiet node")
            wait_until(lambda: f"{fq}:gain" in ros.graph.params(), 30, "the parameter")
            names = ros.graph.params(timeout=1.5)
            assert f"{fq}:gain" in names
            assert not any(n.startswith(quiet.get_fully_qualified_name() + ":") for n in names)
            mine = ros.graph.params(fq, timeout=5)
            assert mine["gain"] == 0.5 and mine["use_sim_time"] is False, mine
    finally:
        quiet.destroy_node()


def test_params_of_a_new_node_need_no_settling_wait(bridge: BridgeProcess, rclpy_robot: Any) -> None:
    """The first params() that reaches a node (its parameter service listed, never called
    by the bridge) answers within a timeout shorter than the bridge's SETTLE_S (1.2 s) wait
    for a newly matched client: listing and reading are sent again if an answer is lost."""
    fq = str(rclpy_robot.get_fully_qualified_name())
    with sync.connect(bridge.url) as ros:
        wait_until(lambda: fq in ros.graph.node_names() and {
            f"{fq}/list_parameters", f"{fq}/get_parameters"} <= set(ros.graph.node(fq).services),
                   15, "the node and its parameter services")
        assert f"{fq}:gain" in ros.graph.params(timeout=1.0)
        assert ros.graph.params(fq, timeout=1.0)["gain"] == 0.5
