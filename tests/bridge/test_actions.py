"""Actions through the bridge, both ways, with raw websocket clients and rclpy peers: what
needs rclpy's action servers and clients (and its converter for every action type). A goal
canceled before any server, an action between two clients and the rosapi action services
are tested in memory in tests/session/test_actions.py."""

from __future__ import annotations

import asyncio
import importlib
import json
import threading
from typing import Any

import cbor2
import pytest
from action_msgs.msg import GoalStatus

from tests.bridge.action_support import (
    FIB,
    FibServer,
    RosCaller,
    bridge_sees_action,
    fib,
    send_goal,
)
from tests.helpers import roundtrip

SUCCEEDED, CANCELED, ABORTED = 4, 5, 6


def _action_types(package: str) -> list[Any]:
    module = importlib.import_module(f"{package}.action")
    return [getattr(module, n) for n in dir(module)
            if not n.startswith("_") and hasattr(getattr(module, n), "Feedback")]


# -- a client sends goals to a ROS action server ---------------------------------------------


async def test_goal_feedback_and_result(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """A goal (args object, ROS 1 type spelling) gets its feedback in order and a SUCCEEDED result."""
    server = FibServer(ros_node, topic)
    ws = await ws_connect()
    await bridge_sees_action(ws, topic)
    await ws.send({"op": "send_action_goal", "action": topic, "action_type": "test_msgs/Fibonacci",
                   "args": {"order": 5}, "feedback": True, "id": "g1"})
    result = await ws.expect(op="action_result", id="g1")
    assert result == {"op": "action_result", "id": "g1", "action": topic,
                      "values": {"sequence": fib(5)}, "status": SUCCEEDED, "result": True}
    feedback = [op for op in ws.backlog if op.get("op") == "action_feedback"]
    # feedback (a topic) may lose the race against the result (a service reply) under
    # load; what arrives is in order, and nothing comes after the result
    sequences = [f["values"]["sequence"] for f in feedback]
    assert sequences and sequences == sorted(sequences, key=len)
    assert all(seq in [fib(i) for i in range(2, 6)] for seq in sequences)
    assert all(f["id"] == "g1" and f["action"] == topic for f in feedback)
    server.destroy()


async def test_goal_args_list_without_feedback(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """args as a list is zipped onto the goal's fields; without feedback: true none is sent."""
    server = FibServer(ros_node, topic)
    ws = await ws_connect()
    await bridge_sees_action(ws, topic)
    await send_goal(ws, topic, [4], "g2")
    result = await ws.expect(op="action_result", id="g2")
    assert result["values"] == {"sequence": fib(4)} and result["result"] is True
    assert server.goals == [4]
    assert [op for op in ws.backlog if op.get("op") == "action_feedback"] == []
    server.destroy()


async def test_goal_answers_in_the_clients_spelling(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """A relative action name works, and replies use the name as the client spelled it."""
    server = FibServer(ros_node, topic)
    ws = await ws_connect()
    await bridge_sees_action(ws, topic)
    await send_goal(ws, topic.lstrip("/"), {"order": 2}, "rel", feedback=True)
    result = await ws.expect(op="action_result", id="rel")
    assert result["action"] == topic.lstrip("/") and result["status"] == SUCCEEDED
    server.destroy()


async def test_rejected_goal(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """A goal the server rejects ends with result false and a text saying so."""
    server = FibServer(ros_node, topic, accept=False)
    ws = await ws_connect()
    await bridge_sees_action(ws, topic)
    await send_goal(ws, topic, {"order": 3}, "rej")
    result = await ws.expect(op="action_result", id="rej")
    assert result["result"] is False and result["status"] == ABORTED
    assert "rejected" in result["values"] and topic in result["values"]
    server.destroy()


async def test_aborted_goal(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """A goal the server aborts ends with its status (6), the result values and result true
    (it ran; rosbridge says false only for a goal that never ran)."""
    server = FibServer(ros_node, topic, abort=True)
    ws = await ws_connect()
    await bridge_sees_action(ws, topic)
    await send_goal(ws, topic, {"order": 3}, "ab")
    result = await ws.expect(op="action_result", id="ab")
    assert result["status"] == ABORTED and result["result"] is True
    assert result["values"] == {"sequence": fib(3)}
    server.destroy()


async def test_cancel_after_acceptance(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """cancel_action_goal after the first feedback cancels the ROS goal: status 5."""
    server = FibServer(ros_node, topic, slow=True)
    ws = await ws_connect()
    await bridge_sees_action(ws, topic)
    await send_goal(ws, topic, {"order": 1}, "c1", feedback=True)
    await ws.expect(op="action_feedback", id="c1")
    await ws.send({"op": "cancel_action_goal", "id": "c1", "action": topic})
    result = await ws.expect(op="action_result", id="c1")
    assert result["status"] == CANCELED and result["result"] is True
    assert result["values"] == {"sequence": [0, 1]}
    assert server.cancel_requests.is_set()
    server.destroy()


async def test_cancel_before_acceptance(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """A cancel that arrives while the server is still deciding cancels the goal once accepted."""
    gate = threading.Event()
    server = FibServer(ros_node, topic, slow=True, gate=gate)
    ws = await ws_connect()
    await bridge_sees_action(ws, topic)
    await send_goal(ws, topic, {"order": 1}, "c2")
    await asyncio.get_running_loop().run_in_executor(None, _wait_goal, server)
    await ws.send({"op": "cancel_action_goal", "id": "c2", "action": topic})
    await roundtrip(ws)
    gate.set()
    result = await ws.expect(op="action_result", id="c2")
    assert result["status"] == CANCELED
    assert server.cancel_requests.is_set()
    server.destroy()


def _wait_goal(server: FibServer) -> None:
    for _ in range(500):
        if server.goals:
            return
        threading.Event().wait(0.02)
    raise AssertionError("the goal never reached the server")


async def test_many_goals_in_flight(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """Thirty goals sent at once on one action each get their own result."""
    server = FibServer(ros_node, topic)
    ws = await ws_connect()
    await bridge_sees_action(ws, topic)
    for n in range(30):
        await send_goal(ws, topic, {"order": n % 10 + 1}, f"m{n}")
    for n in range(30):
        result = await ws.expect(op="action_result", id=f"m{n}")
        assert result["values"] == {"sequence": fib(n % 10 + 1)}, n
    server.destroy()


async def test_several_clients_one_server(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """Goals of three clients to one action server reach the right client each."""
    server = FibServer(ros_node, topic)
    clients = [await ws_connect() for _ in range(3)]
    await bridge_sees_action(clients[0], topic)
    for i, ws in enumerate(clients):
        await send_goal(ws, topic, {"order": i + 2}, "same-id", feedback=True)
    for i, ws in enumerate(clients):
        result = await ws.expect(op="action_result", id="same-id")
        assert result["values"] == {"sequence": fib(i + 2)}
        feedback = [op for op in ws.backlog if op.get("op") == "action_feedback"]
        assert feedback and all(f["values"]["sequence"] == fib(i + 2)[: len(f["values"][
            "sequence"])] for f in feedback)
    server.destroy()


async def test_sender_disconnect_cancels_goal(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """A client that disconnects with a goal in flight has it canceled on the ROS side."""
    server = FibServer(ros_node, topic, slow=True)
    ws = await ws_connect()
    await bridge_sees_action(ws, topic)
    await send_goal(ws, topic, {"order": 1}, "d1", feedback=True)
    await ws.expect(op="action_feedback", id="d1")
    await ws.close()
    got = await asyncio.get_running_loop().run_in_executor(
        None, server.cancel_requests.wait, 10.0
    )
    assert got, "the ROS action server never got a cancel request"
    server.destroy()


async def test_goal_timeout(make_bridge: Any, ws_connect: Any, ros_node: Any, topic: str) -> None:
    """With --goal-timeout, a goal running longer fails with a text and is canceled on ROS.

    The 0.5 s run from the op's arrival: a loaded machine can take longer than that to make
    a new bridge's action client ready, and such a goal ends never sent, saying so. Goals
    go until one reached the server; that one is canceled there.
    """
    bridge = make_bridge("--goal-timeout", "0.5")
    server = FibServer(ros_node, topic, slow=True)
    ws = await ws_connect(bridge.url)
    # an action nobody serves: its goal is never sent, and the text says so
    await send_goal(ws, topic + "_unserved", {"order": 1}, "none")
    result = await ws.expect(op="action_result", id="none")
    assert result["result"] is False and result["values"] == (
        f"{topic}_unserved: the goal timed out after 0.5 s, before an action server was ready "
        "for it (it was never sent)")
    await bridge_sees_action(ws, topic)
    for n in range(1, 21):
        await send_goal(ws, topic, {"order": 1}, f"t{n}")
        result = await ws.expect(op="action_result", id=f"t{n}")
        assert result["result"] is False and "timed out after 0.5 s" in result["values"]
        assert ("canceled on the action server" in result["values"]) != (
            "it was never sent" in result["values"]), result
        if server.goals:
            break
    assert server.goals, "no goal reached the action server"
    got = await asyncio.get_running_loop().run_in_executor(
        None, server.cancel_requests.wait, 10.0
    )
    assert got
    server.destroy()


async def test_cbor_feedback_and_result(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """compression cbor sends feedback and result as CBOR frames; int32[] is a typed array."""
    server = FibServer(ros_node, topic)
    ws = await ws_connect()
    await bridge_sees_action(ws, topic)
    await send_goal(ws, topic, {"order": 4}, "cb", feedback=True, compression="cbor")
    frames = []
    while True:
        frame = await asyncio.wait_for(ws.ws.recv(), 10)
        assert isinstance(frame, bytes), frame
        op = cbor2.loads(frame)
        frames.append(op)
        if op["op"] == "action_result":
            break
    result = frames[-1]
    assert result["status"] == SUCCEEDED and result["result"] is True
    seq = result["values"]["sequence"]
    assert isinstance(seq, cbor2.CBORTag) and seq.tag == 78
    assert list(memoryview(seq.value).cast("i")) == fib(4)
    assert 1 <= len(frames) - 1 <= 3
    assert all(f["op"] == "action_feedback" for f in frames[:-1])
    server.destroy()


async def test_fragmented_result(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """fragment_size splits a large result into fragments that join into the action_result."""
    server = FibServer(ros_node, topic)
    ws = await ws_connect()
    await bridge_sees_action(ws, topic)
    await send_goal(ws, topic, {"order": 40}, "fr", fragment_size=50)
    pieces = []
    while True:
        op = await ws.expect(op="fragment")
        pieces.append(op)
        if op["num"] == op["total"] - 1:
            break
    assert len(pieces) > 2
    result = json.loads("".join(p["data"] for p in pieces))
    assert result["op"] == "action_result" and result["id"] == "fr"
    assert result["values"]["sequence"] == fib(40)
    server.destroy()


# -- a client serves an action to ROS callers ------------------------------------------------


async def _serving(ws_connect: Any, ros_node: Any, topic: str) -> tuple[Any, RosCaller]:
    ws = await ws_connect()
    await ws.send({"op": "advertise_action", "action": topic, "type": FIB})
    caller = RosCaller(ros_node, topic)
    await caller.ready()
    return ws, caller


async def test_serve_action_to_rclpy(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """A ROS goal reaches the client as send_action_goal; its feedback and result reach ROS."""
    ws, caller = await _serving(ws_connect, ros_node, topic)
    handle = await caller.send(3)
    goal = await ws.expect(op="send_action_goal")
    assert goal["action"] == topic and goal["action_type"] == FIB
    assert goal["args"] == {"order": 3} and goal["id"].startswith(f"action_goal:{topic}:")
    await ws.send({"op": "action_feedback", "id": goal["id"], "action": topic,
                   "values": {"sequence": [0, 1, 1]}})
    assert await asyncio.wait_for(caller.feedback.get(), 10) == [0, 1, 1]
    assert handle.status == GoalStatus.STATUS_EXECUTING
    await ws.send({"op": "action_result", "id": goal["id"], "action": topic,
                   "values": {"sequence": fib(3)}, "status": SUCCEEDED, "result": True})
    result = await caller.result(handle)
    assert result.status == GoalStatus.STATUS_SUCCEEDED
    assert list(result.result.sequence) == fib(3)
    caller.destroy()


async def test_served_cancel_from_ros(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """A ROS cancel request reaches the client as cancel_action_goal; it ends the goal canceled."""
    ws, caller = await _serving(ws_connect, ros_node, topic)
    handle = await caller.send(9)
    goal = await ws.expect(op="send_action_goal")
    await handle.cancel_goal_async()
    cancel = await ws.expect(op="cancel_action_goal")
    assert cancel == {"op": "cancel_action_goal", "id": goal["id"], "action": topic}
    await ws.send({"op": "action_result", "id": goal["id"], "action": topic,
                   "values": {"sequence": [0]}, "status": CANCELED, "result": True})
    result = await caller.result(handle)
    assert result.status == GoalStatus.STATUS_CANCELED
    assert list(result.result.sequence) == [0]
    caller.destroy()


@pytest.mark.parametrize("how", ["disconnect", "unadvertise", "result_false", "bad_values"])
async def test_served_goal_aborted_at_once(
    ws_connect: Any, ros_node: Any, topic: str, how: str
) -> None:
    """A serving client that goes away, unadvertises or answers wrongly aborts its goal at once."""
    ws, caller = await _serving(ws_connect, ros_node, topic)
    handle = await caller.send(2)
    goal = await ws.expect(op="send_action_goal")
    if how == "disconnect":
        await ws.close()
    elif how == "unadvertise":
        await ws.send({"op": "unadvertise_action", "action": topic})
    elif how == "result_false":  # roslib's setFailed
        await ws.send({"op": "action_result", "id": goal["id"], "action": topic,
                       "status": ABORTED, "result": False})
    else:
        await ws.send({"op": "action_result", "id": goal["id"], "action": topic,
                       "values": {"sequence": "nope"}, "status": SUCCEEDED, "result": True})
        error = await ws.expect(op="status", level="error")
        assert "values.sequence" in error["msg"] and "aborted" in error["msg"]
    result = await caller.result(handle, timeout=3.0)
    assert result.status == GoalStatus.STATUS_ABORTED
    caller.destroy()


async def test_served_goal_timeout(make_bridge: Any, ws_connect: Any, ros_node: Any, topic: str) -> None:
    """With --goal-timeout, a served goal the client never finishes is aborted; the client is told."""
    bridge = make_bridge("--goal-timeout", "0.5")
    ws = await ws_connect(bridge.url)
    await ws.send({"op": "advertise_action", "action": topic, "type": FIB})
    caller = RosCaller(ros_node, topic)
    await caller.ready()
    handle = await caller.send(2)
    goal = await ws.expect(op="send_action_goal")
    cancel = await ws.expect(op="cancel_action_goal", id=goal["id"])
    assert cancel["action"] == topic
    result = await caller.result(handle)
    assert result.status == GoalStatus.STATUS_ABORTED
    caller.destroy()


async def test_served_many_goals(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """Several ROS goals in flight on one served action are told apart by their ids."""
    ws, caller = await _serving(ws_connect, ros_node, topic)
    handles = [await caller.send(n) for n in range(2, 7)]
    goals = {}
    for _ in handles:
        goal = await ws.expect(op="send_action_goal")
        goals[goal["args"]["order"]] = goal["id"]
    assert len(set(goals.values())) == len(handles)
    for order, gid in reversed(goals.items()):
        await ws.send({"op": "action_result", "id": gid, "action": topic,
                       "values": {"sequence": fib(order)}, "result": True})
    for order, handle in zip(range(2, 7), handles, strict=True):
        result = await caller.result(handle)
        assert result.status == GoalStatus.STATUS_SUCCEEDED
        assert list(result.result.sequence) == fib(order)
    caller.destroy()


async def test_first_owner_keeps_the_action(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """A second client cannot take a served action from a live owner; after unadvertise it can."""
    first, caller = await _serving(ws_connect, ros_node, topic)
    handle = await caller.send(2)
    goal = await first.expect(op="send_action_goal")
    second = await ws_connect()
    await second.send({"op": "advertise_action", "action": topic, "type": FIB, "id": "adv2"})
    error = await second.expect(op="status", level="error", id="adv2")
    assert topic in error["msg"] and "first owner keeps it" in error["msg"]
    await first.send({"op": "action_result", "id": goal["id"], "action": topic,
                      "values": {"sequence": fib(2)}, "result": True})
    assert (await caller.result(handle)).status == GoalStatus.STATUS_SUCCEEDED
    caller.destroy()
    await first.send({"op": "unadvertise_action", "action": topic})
    await roundtrip(first)
    await second.send({"op": "advertise_action", "action": topic, "type": FIB, "id": "adv3"})
    await roundtrip(second)
    assert [op for op in second.backlog if op.get("op") == "status"] == []
    caller = RosCaller(ros_node, topic)
    await caller.ready()
    handle = await caller.send(3)
    goal = await second.expect(op="send_action_goal")
    await second.send({"op": "action_result", "id": goal["id"], "action": topic,
                       "values": {"sequence": fib(3)}, "result": True})
    assert (await caller.result(handle)).status == GoalStatus.STATUS_SUCCEEDED
    caller.destroy()


# -- every action type converts --------------------------------------------------------------


@pytest.mark.parametrize("package", ["test_msgs", "mult_msgs"])
def test_every_action_type_converts(package: str) -> None:
    """Goal, feedback and result of every action in the package convert both ways, JSON and CBOR."""
    from bridge_server.rclpy_graph import convert

    types = _action_types(package)
    assert types, f"{package} has no actions"
    for action in types:
        for part in (action.Goal, action.Feedback, action.Result):
            conv = convert.converter_for(part)
            assert convert.converter_for(part) is conv  # built once
            obj = conv.to_obj(part())
            assert conv.to_obj(conv.from_obj(json.loads(json.dumps(obj)))) == obj
            cbor2.dumps(conv.to_cbor_obj(part()))


@pytest.mark.parametrize("action", [a for p in ("test_msgs", "mult_msgs") for a in _action_types(p)],
                         ids=lambda a: a.__name__)
async def test_every_action_type_through_the_bridge(ws_connect: Any, topic: str, action: Any) -> None:
    """Goal, feedback (CBOR) and result of each action type cross the bridge intact."""
    from bridge_server.rclpy_graph import convert
    from bridge_server.rclpy_graph.types import type_name_of

    type_name = type_name_of(action)
    goal_obj, feedback_obj, result_obj = (
        convert.converter_for(part).to_obj(part()) for part in
        (action.Goal, action.Feedback, action.Result)
    )
    server_ws = await ws_connect()
    await server_ws.send({"op": "advertise_action", "action": topic, "type": type_name})
    ws = await ws_connect()
    await bridge_sees_action(ws, topic)
    await ws.send({"op": "send_action_goal", "action": topic, "action_type": type_name,
                   "args": goal_obj, "feedback": True, "compression": "cbor", "id": "all"})
    goal = await server_ws.expect(op="send_action_goal")
    assert goal["args"] == goal_obj and goal["action_type"] == type_name
    await server_ws.send({"op": "action_feedback", "id": goal["id"], "action": topic,
                          "values": feedback_obj})
    feedback = await ws.expect(op="action_feedback", id="all")
    await server_ws.send({"op": "action_result", "id": goal["id"], "action": topic,
                          "values": result_obj, "result": True})
    result = await ws.expect(op="action_result", id="all")
    assert result["status"] == SUCCEEDED
    for got, want, part in ((feedback, feedback_obj, action.Feedback),
                            (result, result_obj, action.Result)):
        conv = convert.converter_for(part)
        assert conv.to_obj(conv.from_obj(_plain(got["values"]))) == want


def _plain(value: Any) -> Any:
    """A CBOR-decoded value with typed arrays (tags) turned back into lists."""
    if isinstance(value, cbor2.CBORTag):
        codes = {69: "H", 70: "I", 71: "Q", 72: "b", 77: "h", 78: "i", 79: "q", 85: "f", 86: "d"}
        return list(memoryview(value.value).cast(codes[value.tag]))  # type: ignore[call-overload]
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_plain(v) for v in value]
    if isinstance(value, bytes):
        return list(value)
    return value

