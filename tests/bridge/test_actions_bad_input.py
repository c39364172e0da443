"""Bad action input over rclpy: what needs an rclpy action server or client (a duplicate goal
id while a goal runs on rclpy's server, a served goal's feedback or result that does not fit,
answered to an rclpy caller). The rest is tested in memory in
tests/session/test_actions_bad_input.py."""

from __future__ import annotations

from typing import Any

from tests.bridge.action_support import FIB, FibServer, RosCaller, bridge_sees_action, send_goal
from tests.helpers import error_text, sender_and_bystander, still_working


async def test_duplicate_goal_id(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """A second goal with the id of one still in flight is refused; the first goes on."""
    server = FibServer(ros_node, topic, slow=True)
    ws, other = await sender_and_bystander(ws_connect)
    await bridge_sees_action(ws, topic)
    await send_goal(ws, topic, {"order": 1}, "dup", feedback=True)
    await ws.expect(op="action_feedback", id="dup")
    await send_goal(ws, topic, {"order": 1}, "dup")
    msg = await error_text(ws, id="dup")
    assert "already in flight" in msg
    await ws.send({"op": "cancel_action_goal", "id": "dup", "action": topic})
    result = await ws.expect(op="action_result", id="dup")
    assert result["status"] == 5
    await still_working(ws, other, topic)
    server.destroy()


async def test_served_feedback_that_does_not_fit(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """Feedback that does not fit the type names the field; the goal goes on and can succeed."""
    ws, other = await sender_and_bystander(ws_connect)
    await ws.send({"op": "advertise_action", "action": topic, "type": FIB})
    caller = RosCaller(ros_node, topic)
    await caller.ready()
    handle = await caller.send(2)
    goal = await ws.expect(op="send_action_goal")
    await ws.send({"op": "action_feedback", "id": goal["id"], "action": topic,
                   "values": {"sequence": [0.5]}})
    msg = await error_text(ws, id=goal["id"])
    assert "values.sequence[0]" in msg and "int32" in msg
    await ws.send({"op": "action_result", "id": goal["id"], "action": topic,
                   "values": {"sequence": [0, 1, 1]}, "result": True})
    assert (await caller.result(handle)).status == 4
    await still_working(ws, other, topic)
    caller.destroy()


async def test_served_result_with_a_status_that_is_not_final(
    ws_connect: Any, ros_node: Any, topic: str
) -> None:
    """A result whose status is not final (2 executing) is an error, and the goal is aborted."""
    ws, other = await sender_and_bystander(ws_connect)
    await ws.send({"op": "advertise_action", "action": topic, "type": FIB})
    caller = RosCaller(ros_node, topic)
    await caller.ready()
    handle = await caller.send(2)
    goal = await ws.expect(op="send_action_goal")
    await ws.send({"op": "action_result", "id": goal["id"], "action": topic,
                   "values": {"sequence": []}, "result": True, "status": 2})
    msg = await error_text(ws, id=goal["id"])
    assert "status 2" in msg and "aborted" in msg
    assert (await caller.result(handle)).status == 6
    await still_working(ws, other, topic)
    caller.destroy()
