"""Bad action input: the sender is told what was wrong; the connection and a bystander keep working.

In memory (moved from tests/bridge/test_actions_bad_input.py, which keeps the three that
need an rclpy action server or client): the ROS-side action is the bench's robot's.
"""

from __future__ import annotations

from typing import Any

import pytest

from tests.op_peer import FIB, error_text, send_goal, sender_and_bystander, still_working
from tests.session.harness import Robot


async def _failed_goal(ws: Any, id: str) -> tuple[str, dict[str, Any]]:
    """The status error and the failed action_result a refused goal gets."""
    msg = await error_text(ws, id=id)
    result = await ws.expect(op="action_result", id=id)
    assert result["result"] is False and result["status"] == 6
    return msg, result


@pytest.mark.parametrize(
    ("action_type", "named"),
    [
        ("test_msgs/action/NoSuchAction", "test_msgs/action/NoSuchAction"),
        ("nosuch_pkg/Thing", "nosuch_pkg/Thing"),
        ("test_msgs/srv/Fibonacci", "srv"),
        ("Fibonacci", "Fibonacci"),
    ],
)
async def test_unknown_action_type(ws_connect: Any, topic: str, action_type: str, named: str) -> None:
    """An action type that is malformed or not installed is named in the error and the result."""
    ws, other = await sender_and_bystander(ws_connect)
    await ws.send({"op": "send_action_goal", "action": topic, "action_type": action_type,
                   "args": {}, "id": "u1"})
    msg, result = await _failed_goal(ws, "u1")
    assert named in msg and topic in msg
    assert named in result["values"]
    await still_working(ws, other, topic)


async def test_no_such_action_server(ws_connect: Any, topic: str) -> None:
    """A goal to an action nobody serves fails with "does not exist", naming the action."""
    ws, other = await sender_and_bystander(ws_connect)
    await send_goal(ws, topic, {"order": 3}, "n1")
    msg, result = await _failed_goal(ws, "n1")
    assert topic in msg and "does not exist" in msg
    assert "does not exist" in result["values"]
    await still_working(ws, other, topic)


async def test_action_type_differs_from_graph(ws_connect: Any, robot: Robot, topic: str) -> None:
    """A goal whose type differs from the served action's names both types."""
    node = robot.node
    node.serve_action(topic, node.resolve_action(FIB), lambda goal: None, lambda goal: None)
    ws, other = await sender_and_bystander(ws_connect)
    await ws.send({"op": "send_action_goal", "action": topic, "id": "x1",
                   "action_type": "mult_msgs/action/IntegrateImu", "args": {"seconds": 1.0}})
    msg, _ = await _failed_goal(ws, "x1")
    assert "test_msgs/action/Fibonacci" in msg and "mult_msgs/action/IntegrateImu" in msg
    await still_working(ws, other, topic)


@pytest.mark.parametrize(
    ("args", "named"),
    [
        ({"order": "five"}, "args.order"),
        ({"order": 3, "speed": 1}, "speed"),
        ({"order": 2**40}, "args.order"),
        ([1, 2, 3], "3 values"),
    ],
)
async def test_goal_does_not_fit_the_type(ws_connect: Any, topic: str, args: Any, named: str) -> None:
    """A goal that does not fit the type names the field path (or the count of list args)."""
    ws, other = await sender_and_bystander(ws_connect)
    await send_goal(ws, topic, args, "f1")
    msg, result = await _failed_goal(ws, "f1")
    assert named in msg and FIB in msg
    assert named in result["values"]
    await still_working(ws, other, topic)


async def test_args_of_the_wrong_kind(ws_connect: Any, topic: str) -> None:
    """args that is neither an object nor a list is refused, naming the field."""
    ws, other = await sender_and_bystander(ws_connect)
    await send_goal(ws, topic, "order=3", "k1")
    msg = await error_text(ws, id="k1")
    assert "'args'" in msg and "an object or a list" in msg
    await still_working(ws, other, topic)


@pytest.mark.parametrize("op", ["cancel_action_goal", "action_feedback", "action_result"])
async def test_unknown_goal_id(ws_connect: Any, topic: str, op: str) -> None:
    """cancel, feedback or result for a goal id nobody knows is an error naming the id."""
    ws, other = await sender_and_bystander(ws_connect)
    frame: dict[str, Any] = {"op": op, "id": "ghost", "action": topic}
    if op == "action_feedback":
        frame["values"] = {"sequence": [1]}
    if op == "action_result":
        frame.update(values={"sequence": [1]}, result=True, status=4)
    await ws.send(frame)
    msg = await error_text(ws, id="ghost")
    assert op in msg and "'ghost'" in msg and topic in msg
    await still_working(ws, other, topic)


async def test_advertise_unknown_action_type(ws_connect: Any, topic: str) -> None:
    """advertise_action with a type that is not installed names the type."""
    ws, other = await sender_and_bystander(ws_connect)
    await ws.send({"op": "advertise_action", "action": topic, "type": "test_msgs/Nope", "id": "a1"})
    msg = await error_text(ws, id="a1")
    assert "advertise_action" in msg and "test_msgs/Nope" in msg
    await still_working(ws, other, topic)


async def test_unadvertise_not_served(ws_connect: Any, topic: str) -> None:
    """unadvertise_action of an action this client does not serve is an error naming it."""
    ws, other = await sender_and_bystander(ws_connect)
    await ws.send({"op": "unadvertise_action", "action": topic, "id": "ua"})
    msg = await error_text(ws, id="ua")
    assert "unadvertise_action" in msg and topic in msg
    await still_working(ws, other, topic)


@pytest.mark.parametrize("op", ["send_action_goal", "advertise_action"])
async def test_invalid_action_name(ws_connect: Any, topic: str, op: str) -> None:
    """An action name ROS cannot carry is refused with an error naming it."""
    ws, other = await sender_and_bystander(ws_connect)
    bad = topic + "/bad name!"
    frame: dict[str, Any] = {"op": op, "action": bad, "id": "bad"}
    if op == "send_action_goal":
        frame.update(action_type=FIB, args={"order": 1})
    else:
        frame["type"] = FIB
    await ws.send(frame)
    msg = await error_text(ws, id="bad")
    assert "bad name!" in msg and "action" in msg
    if op == "send_action_goal":
        result = await ws.expect(op="action_result", id="bad")
        assert result["result"] is False
    await still_working(ws, other, topic)
