"""The Graph port's contract, asserted on the in-memory Graph and on rclpy's, so the two
cannot drift: each test runs on two nodes of one graph (two MemoryGraph on one MemoryRos;
two RclpyGraph in one ROS domain), and the texts and answers are compared where they must
be equal. ROS discovery has no event, so the rclpy side polls the graph for what it waits
on (async_wait_until); the in-memory side needs no wait at all.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import os
import time
from collections.abc import AsyncIterator, Callable
from typing import Any

import pytest

from rosbridge_core.graph import Graph
from rosbridge_core.interfaces import ServiceCallError
from rosbridge_core.memory.graph import MemoryGraph, MemoryRos
from rosbridge_core.protocol.goal_status import GoalStatus
from tests.helpers import async_wait_until

_names = itertools.count()


class Side:
    """One kind of Graph: makes nodes of one graph, and a node holding parameters."""

    kind = ""

    async def node(self) -> Graph:
        """A new node of the graph."""
        raise NotImplementedError

    async def parameter_node(self, params: dict[str, Any]) -> str:
        """The full name of a node of the graph holding ``params``."""
        raise NotImplementedError

    async def seen(self, test: Callable[[], Any], what: str) -> Any:
        """``test()`` once it holds (the rclpy graph learns of others by discovery)."""
        return await async_wait_until(test, 10, what)

    def close(self) -> None:
        """Drop every node."""


class MemorySide(Side):
    kind = "memory"

    def __init__(self) -> None:
        self.ros = MemoryRos()

    async def node(self) -> Graph:
        return self.ros.node(f"contract_{next(_names)}")

    async def parameter_node(self, params: dict[str, Any]) -> str:
        node = self.ros.node(f"params_{next(_names)}", parameters=params)
        return "/" + node.name

    async def seen(self, test: Callable[[], Any], what: str) -> Any:
        value = test()
        assert value, f"the in-memory graph does not show {what} at once"
        return value

    def close(self) -> None:
        for node in list(self.ros.nodes):
            node.close()


class RclpySide(Side):
    kind = "rclpy"

    def __init__(self, request: pytest.FixtureRequest) -> None:
        self.request = request
        self.graphs: list[Any] = []

    async def node(self) -> Graph:
        from bridge_server.rclpy_graph.graph import RclpyGraph

        graph = RclpyGraph(asyncio.get_running_loop(),
                           name=f"contract_{os.getpid()}_{next(_names)}")
        graph.start()
        self.graphs.append(graph)
        return graph

    async def parameter_node(self, params: dict[str, Any]) -> str:
        node = self.request.getfixturevalue("ros_node")
        for name, value in params.items():
            node.declare_parameter(name, value)
        return str(node.get_fully_qualified_name())

    def close(self) -> None:
        for graph in self.graphs:
            graph.close()


@pytest.fixture(params=["memory", "rclpy"])
async def side(request: pytest.FixtureRequest) -> AsyncIterator[Side]:
    """Each kind of Graph in turn."""
    made = MemorySide() if request.param == "memory" else RclpySide(request)
    yield made
    made.close()


def _message(graph: Graph, type_name: str, obj: dict[str, Any]) -> Any:
    return graph.converter(graph.resolve_message(type_name)).from_obj(obj)


async def test_latched_message_reaches_a_later_subscription(side: Side, topic: str) -> None:
    """A latched publisher's message reaches another node's subscription made after it."""
    a, b = await side.node(), await side.node()
    string = a.resolve_message("std_msgs/msg/String")
    pub = a.acquire_publisher(topic, string, True, 10)
    pub.publish(_message(a, "std_msgs/msg/String", {"data": "hello"}))
    assert await side.seen(lambda: b.topic_types(topic), "the topic's type") == [
        "std_msgs/msg/String"]  # rclpy subscribes transient local if the publisher is
    got: asyncio.Queue[Any] = asyncio.Queue()
    feed = b.subscribe(topic, b.resolve_message("std_msgs/msg/String"), got.put_nowait)
    msg = await asyncio.wait_for(got.get(), 10)
    assert json.loads(msg.json_text()) == {"op": "publish", "topic": topic,
                                           "msg": {"data": "hello"}}
    assert msg.topic == topic and msg.data[:2] == b"\x00\x01"  # CDR, little-endian
    assert feed.latched is msg and feed.type_name == "std_msgs/msg/String"
    a.release_publisher(pub)


async def test_a_failing_listener_keeps_no_other_from_the_message(side: Side, topic: str
                                                                  ) -> None:
    """A listener that raises is passed over: the next listener of the feed still gets it."""
    a, b = await side.node(), await side.node()
    pub = a.acquire_publisher(topic, a.resolve_message("std_msgs/msg/Int32"), True, 10)
    pub.publish(_message(a, "std_msgs/msg/Int32", {"data": 5}))
    await side.seen(lambda: b.topic_types(topic), "the topic's type")

    def broken(msg: Any) -> None:
        raise RuntimeError("a listener's bug")

    got: asyncio.Queue[Any] = asyncio.Queue()
    int32 = b.resolve_message("std_msgs/msg/Int32")
    b.subscribe(topic, int32, broken)
    b.subscribe(topic, int32, got.put_nowait)
    assert json.loads((await asyncio.wait_for(got.get(), 10)).json_text())["msg"] == {"data": 5}
    a.release_publisher(pub)


async def test_subscribing_with_another_type_is_refused(side: Side, topic: str) -> None:
    """A node's subscription has one type: another type is a ValueError naming the first."""
    a = await side.node()
    a.subscribe(topic, a.resolve_message("std_msgs/msg/String"), lambda m: None)
    with pytest.raises(ValueError) as err:
        a.subscribe(topic, a.resolve_message("std_msgs/msg/Int32"), lambda m: None)
    assert str(err.value) == f"topic {topic} is already subscribed with type std_msgs/msg/String"


async def test_unserved_service_fails_with_the_graphs_texts(side: Side, topic: str) -> None:
    """A call to a service nobody serves fails naming it, typed or not."""
    a = await side.node()
    with pytest.raises(ServiceCallError) as untyped:
        await a.call_service(topic, None, {}, 5.0, 0.1)
    assert str(untyped.value) == f"service {topic} does not exist (not in the ROS graph)"
    with pytest.raises(ServiceCallError) as typed:
        await a.call_service(topic, "std_srvs/srv/SetBool", {}, 5.0, 0.1)
    assert str(typed.value) == (f"service {topic} does not exist (not in the ROS graph after "
                                "0.2 s)")


async def test_served_service_answers_and_checks_the_request(side: Side, topic: str) -> None:
    """A node's served service answers another node's call; a request that does not fit
    fails naming its field; ``check`` refuses a built request."""
    a, b = await side.node(), await side.node()
    srv = a.resolve_service("std_srvs/srv/SetBool")
    requests: list[bool] = []

    def on_request(call: Any) -> None:
        requests.append(call.request.data)
        call.complete(call.served.response_conv.from_obj(
            {"success": call.request.data, "message": "done"}))

    served = a.serve(topic, srv, on_request)
    await side.seen(lambda: b.server_types(topic), "the server")
    assert await b.call_service(topic, None, {"data": True}, 10.0, 5.0) == {
        "success": True, "message": "done"}
    assert await b.call_service(topic, "std_srvs/SetBool", [False], 10.0, 5.0) == {
        "success": False, "message": "done"}
    with pytest.raises(ServiceCallError) as bad:
        await b.call_service(topic, None, {"data": 3}, 10.0, 5.0)
    assert str(bad.value).startswith(f"{topic}: bad request: args.data: expected bool")
    with pytest.raises(ServiceCallError) as refused:
        await b.call_service(topic, None, {"data": True}, 10.0, 5.0,
                             check=lambda req: "forbidden" if req.data else None)
    assert str(refused.value) == f"{topic}: forbidden"
    assert requests == [True, False]
    assert b.other_servers(topic) == [f"the ROS node /{a.own_node()[0]}"]
    served.destroy()


class _Goal:
    """What one sent goal reports."""

    def __init__(self) -> None:
        self.events: list[Any] = []
        self.done = asyncio.Event()

    def on_accepted(self) -> None:
        self.events.append("accepted")

    def on_rejected(self) -> None:
        self.events.append("rejected")
        self.done.set()

    def on_feedback(self, feedback: Any) -> None:
        self.events.append(("feedback", list(feedback.sequence)))

    def on_cancel_answer(self, code: int) -> None:
        self.events.append(("cancel", code))

    def on_result(self, status: int, result: Any) -> None:
        self.events.append(("result", status, list(result.sequence)))
        self.done.set()

    def on_failed(self, why: str) -> None:
        self.events.append(("failed", why))
        self.done.set()


async def test_action_goal_feedback_cancel_and_result(side: Side, topic: str) -> None:
    """A goal reaches the node serving the action; its feedback and result come back; a
    canceled goal's server hears the cancel and the client the answer and the status."""
    a, b = await side.node(), await side.node()
    fib = a.resolve_action("test_msgs/action/Fibonacci")
    goals: asyncio.Queue[Any] = asyncio.Queue()
    canceled: asyncio.Queue[Any] = asyncio.Queue()
    served = a.serve_action(topic, fib, goals.put_nowait, canceled.put_nowait)
    client = b.action_client(topic, b.resolve_action("test_msgs/action/Fibonacci"))
    await side.seen(client.ready, "the action server")
    goal_cls = b.converter(client.action_cls.Goal)

    finished = _Goal()
    sent = client.send(goal_cls.from_obj({"order": 3}), finished, True)
    goal = await asyncio.wait_for(goals.get(), 10)
    assert goal.request.order == 3
    await side.seen(lambda: finished.events == ["accepted"], "the acceptance")
    goal.feedback(served.feedback_conv.from_obj({"sequence": [0, 1]}))
    await side.seen(lambda: len(finished.events) == 2, "the feedback")
    assert goal.finish(GoalStatus.SUCCEEDED, served.result_conv.from_obj({"sequence": [0, 1, 1]}))
    assert not goal.finish(GoalStatus.ABORTED)
    await asyncio.wait_for(finished.done.wait(), 10)
    assert finished.events == ["accepted", ("feedback", [0, 1]),
                               ("result", GoalStatus.SUCCEEDED, [0, 1, 1])]
    assert bytes(sent.handle.goal_id.uuid)

    stopped = _Goal()
    sent = client.send(goal_cls.from_obj({"order": 5}), stopped, False)
    goal = await asyncio.wait_for(goals.get(), 10)
    await side.seen(lambda: sent.handle is not None, "the acceptance")
    sent.cancel()
    assert await asyncio.wait_for(canceled.get(), 10) is goal
    goal.finish(GoalStatus.CANCELED)
    await asyncio.wait_for(stopped.done.wait(), 10)
    assert stopped.events == ["accepted", ("cancel", 0), ("result", GoalStatus.CANCELED, [])]
    assert await side.seen(lambda: b.server_types(topic + "/_action/send_goal"),
                           "the action's send_goal server") == [
        "test_msgs/action/Fibonacci_SendGoal"]
    served.destroy()
    client.destroy()


async def test_node_parameters(side: Side) -> None:
    """Another node's parameters are listed, read and set, a value of another type refused
    with rclpy's reason; a node that is not there is a LookupError naming its parameter
    service."""
    a = await side.node()
    node = await side.parameter_node({"speed": 1.5, "name": "robot"})
    assert {"speed", "name"} <= set(await a.parameter_names(node, 10.0))
    assert await a.get_parameter(node, "speed") == (True, 1.5)
    assert await a.get_parameter(node, "missing") == (False, None)
    assert await a.set_parameter(node, "name", "rover") == (True, "")
    assert await a.get_parameter(node, "name") == (True, "rover")
    assert await a.set_parameter(node, "speed", "fast") == (
        False, "Wrong parameter type, expected 'Type.DOUBLE' got 'Type.STRING'")
    assert await a.get_parameter(node, "speed") == (True, 1.5)
    if side.kind == "memory":  # rclpy waits PARAM_DISCOVERY (5 s) for a node that is not there
        with pytest.raises(LookupError) as gone:
            await a.get_parameter("/nobody", "x")
        assert str(gone.value) == ("service /nobody/get_parameters does not exist (not in the "
                                   "ROS graph)")


async def test_introspection_and_clock(side: Side, topic: str) -> None:
    """The graph lists its nodes, a node's endpoints and publishers; now() is the clock."""
    a, b = await side.node(), await side.node()
    pub = a.acquire_publisher(topic, a.resolve_message("std_msgs/msg/Int32"), False, 10)
    me = a.own_node()
    assert me in await side.seen(lambda: b.node_names() if me in b.node_names() else None,
                                 "the other node")
    await side.seen(lambda: b.topic_publishers(topic) == [me], "the publisher")
    assert (topic, ["std_msgs/msg/Int32"]) in b.topic_names_and_types()
    assert topic in (await side.seen(lambda: b.node_endpoints(*me)[1], "the endpoints"))
    assert a.publisher_types(topic) == {"std_msgs/msg/Int32"} and not b.publisher_types(topic)
    qos = b.topic_publishers_qos(topic)[0][2]
    assert (qos["reliability"], qos["durability"]) == ("reliable", "volatile")
    sec, nsec = a.now()
    assert abs(sec + nsec / 1e9 - time.time()) < 5
    a.release_publisher(pub)


# -- what both sides read from the type definitions ---------------------------------------------


@pytest.fixture
async def both() -> AsyncIterator[tuple[Graph, Graph]]:
    """A MemoryGraph and an RclpyGraph, side by side."""
    from bridge_server.rclpy_graph.graph import RclpyGraph

    rclpy_graph = RclpyGraph(asyncio.get_running_loop(), name=f"types_{os.getpid()}")
    yield MemoryGraph(MemoryRos()), rclpy_graph


@pytest.mark.parametrize(("name", "kind", "part"), [
    ("sensor_msgs/msg/Imu", "msg", None),
    ("visualization_msgs/msg/MarkerArray", "msg", None),
    ("sensor_msgs/msg/NavSatStatus", "msg", None),  # constants
    ("std_srvs/srv/SetBool", "srv", "Request"),
    ("rcl_interfaces/srv/SetParameters", "srv", "Response"),
    ("test_msgs/action/Fibonacci", "action", "Feedback"),
])
def test_typedefs_are_the_same(both: tuple[Graph, Graph], name: str, kind: str,
                               part: str | None) -> None:
    """rosapi typedefs from msgs equal those from rclpy, constants and nested types too."""
    memory, rclpy_graph = both
    assert memory.typedefs(name, kind, part) == rclpy_graph.typedefs(name, kind, part)


@pytest.mark.parametrize("name", [
    "geometry_msgs/msg/PoseStamped", "std_srvs/srv/SetBool", "rcl_interfaces/srv/GetParameters",
    "test_msgs/action/Fibonacci", "sensor_msgs/Imu",
])
def test_interface_definitions_are_the_same(both: tuple[Graph, Graph], name: str) -> None:
    """A type's full definition text (ros2msg layout) from msgs equals the installed one."""
    memory, rclpy_graph = both
    assert memory.interface_definition(name) == rclpy_graph.interface_definition(name)
