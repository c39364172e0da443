"""Service ops of a session, in memory (moved from tests/bridge/test_ops_services.py, which
keeps what needs rclpy): call_service's argument forms and fragments, services a client
advertises and answers (to a ROS caller or to another client), their owners, and answers
of the wrong shape.

The caller or server on the ROS side is the bench's robot node of the in-memory graph: it
is there at once, so no test waits for discovery.
"""

from __future__ import annotations

import asyncio
import json
from typing import Any

from rosbridge_core.protocol.frames import split_fragments
from tests.op_peer import roundtrip
from tests.session.harness import Robot


def _mult(robot: Robot, name: str) -> None:
    robot.serve(name, "mult_msgs/srv/MultFloats", lambda a: {"result": a["x"] * a["y"]})


async def test_call_service_args_list_without_type(ws_connect: Any, robot: Robot, topic: str) -> None:
    """call_service with args as a list (zipped onto the request fields) and the type from the graph."""
    _mult(robot, topic)
    ws = await ws_connect()
    await ws.send({"op": "call_service", "service": topic, "args": [2, 5], "id": 7,
                   "timeout": 30})
    reply = await ws.expect(op="service_response", id=7)
    assert reply["result"] is True
    assert reply["values"] == {"result": 10.0}


async def test_call_service_short_type_spelling(ws_connect: Any, robot: Robot, topic: str) -> None:
    """The ``pkg/Type`` spelling of a service type works too."""
    robot.serve(topic, "std_srvs/srv/SetBool",
                lambda a: {"success": a["data"], "message": f"was {a['data']}"})
    ws = await ws_connect()
    await ws.send({"op": "call_service", "service": topic, "type": "std_srvs/SetBool",
                   "args": {"data": True}, "id": "sb", "timeout": 30})
    reply = await ws.expect(op="service_response", id="sb")
    assert reply["values"] == {"success": True, "message": "was True"}


async def test_slow_call_does_not_block_connection(ws_connect: Any, robot: Robot, topic: str) -> None:
    """A slow call runs concurrently: a later fast call on the same connection answers first."""
    robot.serve(topic + "_slow", "std_srvs/srv/SetBool", None)
    _mult(robot, topic + "_fast")
    ws = await ws_connect()
    await ws.send({"op": "call_service", "service": topic + "_slow",
                   "type": "std_srvs/SetBool", "id": "slow"})
    await ws.send({"op": "call_service", "service": topic + "_fast",
                   "type": "mult_msgs/MultFloats", "args": {"x": 1, "y": 2}, "id": "fast",
                   "timeout": 30})
    first = await ws.recv()
    assert first["id"] == "fast" and first["values"] == {"result": 2.0}
    await robot.answer_held(topic + "_slow", {"success": True, "message": ""})
    last = await ws.expect(op="service_response", id="slow")
    assert last["result"] is True


async def test_advertise_service_answers_a_graph_caller(ws_connect: Any, robot: Robot,
                                                        topic: str) -> None:
    """After advertise_service, a call from another node reaches the client, its id naming
    the service, and gets the client's answer."""
    ws = await ws_connect()
    await ws.send({"op": "advertise_service", "service": topic, "type": "mult_msgs/MultFloats"})
    await roundtrip(ws)
    future = robot.call(topic, "mult_msgs/srv/MultFloats", {"x": 6.0, "y": 7.0})
    request = await ws.expect(op="call_service", service=topic)
    assert request["args"] == {"x": 6.0, "y": 7.0}
    assert request["id"].startswith(f"service_request:{topic}:")
    await ws.send({"op": "service_response", "service": topic, "id": request["id"],
                   "result": True, "values": {"result": request["args"]["x"] * 7}})
    assert (await asyncio.wait_for(future, 10))["result"] == 42.0


async def _serve_set_bool(ws: Any, name: str) -> None:
    await ws.send({"op": "advertise_service", "service": name, "type": "std_srvs/srv/SetBool"})
    await roundtrip(ws)


async def test_served_service_failure_is_not_answered_with_a_default(
    ws_connect: Any, robot: Robot, topic: str
) -> None:
    """A client answering result false leaves the ROS caller unanswered (no invented default)."""
    ws = await ws_connect()
    await _serve_set_bool(ws, topic)
    failed = robot.call(topic, "std_srvs/srv/SetBool", {"data": True})
    request = await ws.expect(op="call_service", service=topic)
    await ws.send({"op": "service_response", "service": topic, "id": request["id"],
                   "result": False, "values": "cannot do that"})
    later = robot.call(topic, "std_srvs/srv/SetBool", {"data": False})
    request = await ws.expect(op="call_service", service=topic)
    await ws.send({"op": "service_response", "service": topic, "id": request["id"],
                   "result": True, "values": {"success": True, "message": "second"}})
    assert (await asyncio.wait_for(later, 10))["message"] == "second"
    assert not failed.done()
    failed.cancel()


async def test_first_owner_keeps_a_served_service(ws_connect: Any, robot: Robot, topic: str) -> None:
    """A second client advertising a service another client serves is refused; the first keeps it."""
    first = await ws_connect()
    await _serve_set_bool(first, topic)
    second = await ws_connect()
    await second.send({"op": "advertise_service", "service": topic, "type": "std_srvs/SetBool",
                       "id": "again"})
    refused = await second.expect(op="status", id="again")
    assert refused["level"] == "error" and "already served" in refused["msg"]
    future = robot.call(topic, "std_srvs/srv/SetBool", {"data": True})
    request = await first.expect(op="call_service", service=topic)
    await first.send({"op": "service_response", "service": topic, "id": request["id"],
                      "result": True, "values": {"success": True, "message": "first"}})
    assert (await asyncio.wait_for(future, 10))["message"] == "first"


async def test_fragmented_call_service(ws_connect: Any, robot: Robot, topic: str) -> None:
    """A call_service op sent as fragment ops is reassembled and carried out."""
    _mult(robot, topic)
    ws = await ws_connect()
    text = json.dumps({"op": "call_service", "service": topic, "type": "mult_msgs/MultFloats",
                       "args": {"x": 1.5, "y": 2.0}, "id": "frag", "timeout": 30})
    pieces = split_fragments(text, 10, "f1")
    assert len(pieces) > 3
    for piece in reversed(pieces):  # any order
        await ws.send_raw(piece)
    reply = await ws.expect(op="service_response", id="frag")
    assert reply["values"] == {"result": 3.0}


async def test_call_service_fragment_size(ws_connect: Any, robot: Robot, topic: str) -> None:
    """A call_service with fragment_size gets its service_response as fragment ops."""
    _mult(robot, topic)
    ws = await ws_connect()
    await ws.send({"op": "call_service", "service": topic, "type": "mult_msgs/MultFloats",
                   "args": {"x": 2.0, "y": 2.0}, "id": "fr", "fragment_size": 20,
                   "timeout": 30})
    first = await ws.expect(op="fragment", id="fr")
    pieces = {first["num"]: first["data"]}
    while len(pieces) < first["total"]:
        frag = await ws.expect(op="fragment", id="fr")
        pieces[frag["num"]] = frag["data"]
    reply = json.loads("".join(pieces[i] for i in range(first["total"])))
    assert reply == {"op": "service_response", "service": topic, "result": True,
                     "values": {"result": 4.0}, "id": "fr"}


async def test_client_to_client_call_keeps_failure(ws_connect: Any, topic: str) -> None:
    """A call to a service another client of the bridge serves gets its answer, failures included."""
    server = await ws_connect()
    await _serve_set_bool(server, topic)
    caller = await ws_connect()
    await caller.send({"op": "call_service", "service": topic, "args": {"data": True},
                       "id": "ok"})
    request = await server.expect(op="call_service", service=topic)
    assert request["args"] == {"data": True}
    await server.send({"op": "service_response", "service": topic, "id": request["id"],
                       "result": True, "values": {"success": True, "message": "fine"}})
    reply = await caller.expect(op="service_response", id="ok")
    assert reply["result"] is True and reply["values"] == {"success": True, "message": "fine"}
    await caller.send({"op": "call_service", "service": topic, "args": {"data": False},
                       "id": "bad"})
    request = await server.expect(op="call_service", service=topic)
    await server.send({"op": "service_response", "service": topic, "id": request["id"],
                       "result": False, "values": "handler raised ValueError"})
    reply = await caller.expect(op="service_response", id="bad")
    assert reply["result"] is False and "handler raised ValueError" in reply["values"]
    await caller.send({"op": "call_service", "service": topic, "id": "gone", "timeout": 30})
    await server.expect(op="call_service", service=topic)
    await server.close()
    reply = await caller.expect(op="service_response", id="gone")
    assert reply["result"] is False and topic in reply["values"]


async def test_answers_of_other_shapes_are_named_and_leave_the_caller_waiting(
    ws_connect: Any, robot: Robot, topic: str
) -> None:
    """A service_response not in the usual shape (taken as decoded) gets the generic path's
    error naming what is wrong, and the ROS caller still waits for a good answer."""
    ws = await ws_connect()
    await _serve_set_bool(ws, topic)
    future = robot.call(topic, "std_srvs/srv/SetBool", {"data": True})
    request = await ws.expect(op="call_service", service=topic)
    rid = request["id"]
    wrong: list[tuple[dict[str, Any], str]] = [
        ({"result": "yes", "values": {"success": True}}, "field 'result' must be true or false"),
        ({"result": True, "values": [True]}, "field 'values' must be an object or a string"),
        ({"result": True, "values": {"success": True}, "service": ""},
         "field 'service' must be a non-empty string"),
        ({"result": True, "values": {"success": True}, "id": rid + "x"}, "no ROS call"),
        ({"result": True, "values": {"success": "very"}}, "the ROS caller is not answered"),
    ]
    for n, (fields, why) in enumerate(wrong):
        await ws.send({"op": "service_response", "service": topic, "id": rid, **fields})
        error = await ws.expect(op="status", level="error")
        assert why in error["msg"], (n, error)
        assert not future.done()
    future.cancel()
    # a bad response (its value does not convert) took the call; the next call is answered
    # with the service named as the client spelled it, without the leading slash
    future = robot.call(topic, "std_srvs/srv/SetBool", {"data": False})
    request = await ws.expect(op="call_service", service=topic)
    await ws.send({"op": "service_response", "service": topic.lstrip("/"), "id": request["id"],
                   "result": True, "values": {"success": True, "message": "at last"}})
    assert (await asyncio.wait_for(future, 10))["message"] == "at last"


async def test_a_call_between_clients_times_out_with_its_own_timeout(
    ws_connect: Any, topic: str
) -> None:
    """A call to a service another client serves fails after the call's own timeout when
    that client does not answer; its late answer then finds no call waiting."""
    server = await ws_connect()
    await _serve_set_bool(server, topic)
    caller = await ws_connect()
    await caller.send({"op": "call_service", "service": topic, "args": {"data": True},
                       "id": "slow", "timeout": 0.5})
    request = await server.expect(op="call_service", service=topic)
    reply = await caller.expect(op="service_response", id="slow")
    assert reply["result"] is False and "timed out after 0.5 s" in reply["values"]
    await server.send({"op": "service_response", "service": topic, "id": request["id"],
                       "result": True, "values": {"success": True, "message": "late"}})
    error = await server.expect(op="status", level="error")
    assert "no ROS call" in error["msg"]
