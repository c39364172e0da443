"""Action ops of a session, in memory (moved from tests/bridge/test_actions.py, which keeps
what needs rclpy action servers and clients): a goal canceled while no server is there yet,
an action between two clients, and the rosapi action services.

The robot node serves the ROS-side action where one is needed; the in-memory graph lists it
at once.
"""

from __future__ import annotations

from typing import Any

from tests.op_peer import FIB, fib, rosapi, roundtrip, send_goal
from tests.session.harness import Robot

SUCCEEDED, CANCELED = 4, 5


async def test_cancel_while_waiting_for_a_server(ws_connect: Any, topic: str) -> None:
    """A goal canceled while the bridge still waits for an action server ends canceled at once."""
    ws = await ws_connect()
    await send_goal(ws, topic, {"order": 1}, "w1")
    await ws.send({"op": "cancel_action_goal", "id": "w1", "action": topic})
    result = await ws.expect(op="action_result", id="w1")
    assert result["status"] == CANCELED and result["result"] is False
    assert "canceled before it was sent" in result["values"]


async def test_client_to_client_action(ws_connect: Any, topic: str) -> None:
    """A goal one client sends reaches an action another client serves, and back."""
    server_ws = await ws_connect()
    await server_ws.send({"op": "advertise_action", "action": topic, "type": FIB})
    await roundtrip(server_ws)
    ws = await ws_connect()
    await send_goal(ws, topic, {"order": 3}, "cc", feedback=True)
    goal = await server_ws.expect(op="send_action_goal")
    await server_ws.send({"op": "action_feedback", "id": goal["id"], "action": topic,
                          "values": {"sequence": [0, 1]}})
    feedback = await ws.expect(op="action_feedback", id="cc")
    assert feedback["values"] == {"sequence": [0, 1]}
    await server_ws.send({"op": "action_result", "id": goal["id"], "action": topic,
                          "values": {"sequence": fib(3)}, "result": True})
    result = await ws.expect(op="action_result", id="cc")
    assert result["status"] == SUCCEEDED and result["values"] == {"sequence": fib(3)}


async def test_rosapi_action_calls(ws_connect: Any, robot: Robot, topic: str) -> None:
    """action_servers lists graph- and client-served actions; action_type and *_details answer."""
    node = robot.node
    node.serve_action(topic, node.resolve_action(FIB), lambda goal: None, lambda goal: None)
    ws = await ws_connect()
    served = topic + "_served"
    await ws.send({"op": "advertise_action", "action": served, "type": "mult_msgs/IntegrateImu"})
    listed = (await rosapi(ws, "/rosapi/action_servers"))["action_servers"]
    assert topic in listed and served in listed
    assert await rosapi(ws, "/rosapi/action_type", {"action": topic}) == {"type": FIB}
    assert await rosapi(ws, "/rosapi/action_type", [served]) == {
        "type": "mult_msgs/action/IntegrateImu"}
    assert await rosapi(ws, "/rosapi/action_type", {"action": topic + "_none"}) == {"type": ""}
    goal = await rosapi(ws, "/rosapi/action_goal_details", {"type": "mult_msgs/IntegrateImu"})
    assert goal["typedefs"][0]["type"] == "mult_msgs/action/IntegrateImu_Goal"
    assert goal["typedefs"][0]["fieldnames"] == ["seconds"]
    result = await rosapi(ws, "/rosapi/action_result_details", {"type": FIB})
    assert result["typedefs"][0]["fieldnames"] == ["sequence"]
    assert result["typedefs"][0]["fieldarraylen"] == [0]
    feedback = await rosapi(ws, "/rosapi/action_feedback_details",
                            {"type": "mult_msgs/action/IntegrateImu"})
    assert [t["type"] for t in feedback["typedefs"]] == [
        "mult_msgs/action/IntegrateImu_Feedback", "geometry_msgs/msg/Vector3"]
    assert feedback["typedefs"][0]["fieldnames"] == ["sum", "elapsed"]
    services = await rosapi(ws, "/rosapi/services")
    assert "/rosapi/action_goal_details" in services["services"]
    await ws.send({"op": "call_service", "service": "/rosapi/action_goal_details",
                   "args": {"type": "test_msgs/action/Nope"}, "id": "bad"})
    reply = await ws.expect(op="service_response", id="bad")
    assert reply["result"] is False and "test_msgs/action/Nope" in reply["values"]
