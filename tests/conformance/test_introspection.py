"""``ros.graph``, one suite on two backends: MockRos answers what it holds as the bridge does.

What is listed is what the client itself made (a topic advertised, a subscription, a
served service and action), so both backends know it; on the bridge it is the ROS graph,
through /rosapi. The graph takes a moment to settle on the bridge (discovery sends no
event): :func:`until` asks again, with a deadline.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Any, TypeVar

import pytest

from roslibpy_lite import MockRos, Ros, ServiceError, UsageError
from roslibpy_lite.capabilities.introspection import GraphAction, GraphService, GraphTopic
from roslibpy_lite.transports.memory import MOCK_NODE
from tests.conformance.test_actions import IMU, counting
from tests.op_peer import ask_until

T = TypeVar("T")


async def until(ask: Callable[[], Awaitable[T]], ok: Callable[[T], bool],
                timeout: float = 15.0) -> T:
    """Ask until the answer is ``ok`` (the ROS graph settles with no event), with a deadline."""
    return await ask_until(ask, ok, "the graph", timeout)


async def test_topics_services_actions_with_types(ros: Ros, topic: str) -> None:
    """What the client advertises, serves and subscribes to is listed with its type."""
    await ros.advertise(topic + "_out", "std_msgs/msg/String")
    await ros.subscribe(topic + "_in", "std_msgs/msg/Int32")
    await ros.advertise_service(topic + "_srv", "mult_msgs/srv/MultFloats",
                                lambda req: {"result": 0.0})
    await ros.advertise_action(topic + "_act", IMU, counting)
    graph = ros.graph
    topics = await until(graph.topics, lambda ts: {t.name for t in ts} >= {
        topic + "_out", topic + "_in"})
    assert GraphTopic(topic + "_out", "std_msgs/msg/String") in topics
    assert GraphTopic(topic + "_in", "std_msgs/msg/Int32") in topics
    assert topics == sorted(topics)
    services = await until(graph.services, lambda s: topic + "_srv" in {x.name for x in s})
    assert GraphService(topic + "_srv", "mult_msgs/srv/MultFloats") in services
    assert GraphService("/rosapi/topics", "rosapi_msgs/srv/Topics") in services
    actions = await until(graph.actions, lambda a: topic + "_act" in {x.name for x in a})
    assert GraphAction(topic + "_act", IMU) in actions
    assert await graph.topic_type(topic + "_out") == "std_msgs/msg/String"
    assert await graph.service_type(topic + "_srv") == "mult_msgs/srv/MultFloats"
    assert await graph.action_type(topic + "_act") == IMU


async def test_unknown_names(ros: Ros, topic: str) -> None:
    """A name nobody uses has no type (None); an unknown node fails saying it is not there."""
    assert await ros.graph.topic_type(topic + "_nobody") is None
    assert await ros.graph.service_type(topic + "_nobody") is None
    assert await ros.graph.action_type(topic + "_nobody") is None
    with pytest.raises(ServiceError, match=r"node /no_such_node_here is not in the ROS graph"):
        await ros.graph.node("/no_such_node_here")
    with pytest.raises(UsageError, match="topic name"):
        await ros.graph.topic_type("")


async def test_the_node_that_holds_our_interfaces(ros: Ros, topic: str) -> None:
    """The node publishing for the client (the bridge's, or MockRos's) lists what it holds."""
    await ros.advertise(topic + "_out", "std_msgs/msg/String")
    await ros.subscribe(topic + "_in", "std_msgs/msg/Int32")
    await ros.advertise_service(topic + "_srv", "mult_msgs/srv/MultFloats",
                                lambda req: {"result": 0.0})

    def holder(nodes: list[Any]) -> Any:
        return next((n for n in nodes if topic + "_out" in n.publishers), None)

    nodes = await until(ros.graph.nodes, lambda ns: holder(ns) is not None and topic + "_in"
                        in holder(ns).subscribers and topic + "_srv" in holder(ns).services)
    node = holder(nodes)
    assert node.name in await ros.graph.node_names()
    assert await ros.graph.node(node.name) == node
    if isinstance(ros, MockRos):
        assert node.name == MOCK_NODE


@pytest.fixture
async def param_node(ros: Ros, request: pytest.FixtureRequest) -> str:
    """A node with parameters ``speed`` (1.5) and ``names`` (["a", "b"]): an rclpy node's on
    the bridge, the store's on MockRos."""
    if isinstance(ros, MockRos):
        name = "/mock_params"
        ros.add_node(name, {"speed": 1.5, "names": ["a", "b"]})
        return name
    node = request.getfixturevalue("ros_node")
    node.declare_parameter("speed", 1.5)
    node.declare_parameter("names", ["a", "b"])
    return str(node.get_fully_qualified_name())


async def test_parameters(ros: Ros, param_node: str) -> None:
    """Parameters are listed, read, written (a value of another type is refused) and tested."""
    speed = f"{param_node}:speed"
    await until(ros.graph.params, lambda names: speed in names, timeout=30)
    assert param_node in await ros.graph.node_names()
    assert await ros.graph.get_param(speed) == 1.5
    assert await ros.graph.get_param(f"{param_node}:names") == ["a", "b"]
    assert await ros.graph.get_param(f"{param_node}:nope") is None
    assert await ros.graph.get_param(f"{param_node}:nope", 7) == 7
    await ros.graph.set_param(speed, 2.25)
    assert await ros.graph.get_param(speed) == 2.25
    with pytest.raises(ServiceError, match=rf"{speed}: the node refused the value"):
        await ros.graph.set_param(speed, "fast")
    assert await ros.graph.has_param(speed) is True
    assert await ros.graph.has_param(f"{param_node}:nope") is False


async def test_parameter_misuse_is_named(ros: Ros) -> None:
    """A parameter name without its node, or a value JSON cannot carry, fails at the call."""
    with pytest.raises(UsageError, match=r"'speed': expected '/node:param'"):
        await ros.graph.get_param("speed")
    with pytest.raises(UsageError, match=r"set_param /n:p: .*not JSON serializable"):
        await ros.graph.set_param("/n:p", object())
