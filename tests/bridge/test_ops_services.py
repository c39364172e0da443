"""Service ops on the wire: call_service to ROS, client-served services, fragments."""

from __future__ import annotations

import asyncio
import json
import threading
import time
from typing import Any

from mult_msgs.srv import MultFloats
from rclpy.callback_groups import ReentrantCallbackGroup
from std_srvs.srv import SetBool

from rosbridge_core.protocol.frames import split_fragments
from tests.bridge.support import ros_future, roundtrip, serve_set_bool, wait_service
from tests.helpers import async_wait_until


def _mult(ros_node: Any, name: str) -> Any:
    def handle(req: Any, resp: Any) -> Any:
        resp.result = req.x * req.y
        return resp

    return ros_node.create_service(MultFloats, name, handle)


async def _bridge_sees_service(ws: Any, name: str) -> None:
    n = 0
    while True:
        n += 1
        await ws.send(
            {"op": "call_service", "service": "/rosapi/service_type", "args": {"service": name},
             "id": f"st{n}"}
        )
        reply = await ws.expect(op="service_response", id=f"st{n}")
        if reply["values"]["type"]:
            return
        assert n < 500, f"the bridge never saw {name}"
        await asyncio.sleep(0.02)


async def test_call_service_args_object_with_type(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """call_service with an args object and a type reaches an rclpy service and returns its answer."""
    _mult(ros_node, topic)
    ws = await ws_connect()
    await ws.send({"op": "call_service", "service": topic, "type": "mult_msgs/srv/MultFloats",
                   "args": {"x": 3.0, "y": 4.5}, "id": "c1", "timeout": 30})
    reply = await ws.expect(op="service_response", id="c1")
    assert reply == {"op": "service_response", "service": topic, "result": True,
                     "values": {"result": 13.5}, "id": "c1"}


async def test_call_service_args_list_without_type(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """call_service with args as a list (zipped onto the request fields) and the type from the graph."""
    _mult(ros_node, topic)
    ws = await ws_connect()
    await _bridge_sees_service(ws, topic)
    await ws.send({"op": "call_service", "service": topic, "args": [2, 5], "id": 7,
                   "timeout": 30})
    reply = await ws.expect(op="service_response", id=7)
    assert reply["result"] is True
    assert reply["values"] == {"result": 10.0}


async def test_call_service_short_type_spelling(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """The ``pkg/Type`` spelling of a service type works too."""
    ros_node.create_service(SetBool, topic, lambda req, resp: _set_bool(req, resp))
    ws = await ws_connect()
    await ws.send({"op": "call_service", "service": topic, "type": "std_srvs/SetBool",
                   "args": {"data": True}, "id": "sb", "timeout": 30})
    reply = await ws.expect(op="service_response", id="sb")
    assert reply["values"] == {"success": True, "message": "was True"}


def _set_bool(req: Any, resp: Any) -> Any:
    resp.success = req.data
    resp.message = f"was {req.data}"
    return resp


async def test_call_service_timeout(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """A service that does not answer in time fails with result false naming the timeout."""
    release = threading.Event()
    finished = threading.Event()

    def slow(req: Any, resp: Any) -> Any:
        if req.data:  # the first call (data false) answers at once: the bridge has found it
            release.wait(30)
            finished.set()
        return resp

    ros_node.create_service(SetBool, topic, slow, callback_group=ReentrantCallbackGroup())
    ws = await ws_connect()
    try:
        await ws.send({"op": "call_service", "service": topic, "type": "std_srvs/srv/SetBool",
                       "args": {"data": False}, "timeout": 30, "id": "warm"})
        assert (await ws.expect(op="service_response", id="warm"))["result"] is True
        await ws.send({"op": "call_service", "service": topic, "type": "std_srvs/srv/SetBool",
                       "args": {"data": True}, "timeout": 0.5, "id": "slow"})
        reply = await ws.expect(op="service_response", id="slow")
    finally:
        release.set()
        await asyncio.to_thread(finished.wait, 10)  # let the callback answer before teardown
    assert reply["result"] is False
    assert isinstance(reply["values"], str)
    assert "timed out" in reply["values"] and "0.5" in reply["values"]
    assert topic in reply["values"]


async def test_slow_call_does_not_block_connection(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """A slow call runs concurrently: a later fast call on the same connection answers first."""
    release = threading.Event()
    finished = threading.Event()

    def slow(req: Any, resp: Any) -> Any:
        release.wait(30)
        finished.set()
        resp.success = True
        return resp

    group = ReentrantCallbackGroup()
    ros_node.create_service(SetBool, topic + "_slow", slow, callback_group=group)
    _mult(ros_node, topic + "_fast")
    ws = await ws_connect()
    try:
        await ws.send({"op": "call_service", "service": topic + "_slow",
                       "type": "std_srvs/SetBool", "id": "slow"})
        await ws.send({"op": "call_service", "service": topic + "_fast",
                       "type": "mult_msgs/MultFloats", "args": {"x": 1, "y": 2}, "id": "fast", "timeout": 30})
        first = await ws.recv()
        assert first["id"] == "fast" and first["values"] == {"result": 2.0}
    finally:
        release.set()
        await asyncio.to_thread(finished.wait, 10)  # let the callback answer before teardown
    last = await ws.expect(op="service_response", id="slow")
    assert last["result"] is True


async def test_advertise_service_answers_ros_caller(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """After advertise_service, an rclpy client's call reaches the client and gets its answer."""
    ws = await ws_connect()
    await ws.send({"op": "advertise_service", "service": topic, "type": "mult_msgs/MultFloats"})
    client = ros_node.create_client(MultFloats, topic)
    await wait_service(client)
    future = client.call_async(MultFloats.Request(x=6.0, y=7.0))
    request = await ws.expect(op="call_service", service=topic)
    assert request["args"] == {"x": 6.0, "y": 7.0}
    assert request["id"].startswith(f"service_request:{topic}:")
    await ws.send({"op": "service_response", "service": topic, "id": request["id"],
                   "result": True, "values": {"result": request["args"]["x"] * 7}})
    response = await ros_future(future)
    assert response.result == 42.0


async def test_served_service_failure_is_not_answered_with_a_default(
    ws_connect: Any, ros_node: Any, topic: str
) -> None:
    """A client answering result false leaves the ROS caller unanswered (no invented default)."""
    ws = await ws_connect()
    client = await serve_set_bool(ws, ros_node, topic)
    failed = client.call_async(SetBool.Request(data=True))
    request = await ws.expect(op="call_service", service=topic)
    await ws.send({"op": "service_response", "service": topic, "id": request["id"],
                   "result": False, "values": "cannot do that"})
    later = client.call_async(SetBool.Request(data=False))
    request = await ws.expect(op="call_service", service=topic)
    await ws.send({"op": "service_response", "service": topic, "id": request["id"],
                   "result": True, "values": {"success": True, "message": "second"}})
    assert (await ros_future(later)).message == "second"
    assert not failed.done()


async def test_unadvertise_service(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """unadvertise_service removes the ROS service at once; waiting callers get no default."""
    ws = await ws_connect()
    await ws.send({"op": "advertise_service", "service": topic, "type": "std_srvs/SetBool"})
    client = ros_node.create_client(SetBool, topic)
    await wait_service(client)
    future = client.call_async(SetBool.Request(data=True))
    await ws.expect(op="call_service", service=topic)
    await ws.send({"op": "unadvertise_service", "service": topic})
    await async_wait_until(lambda: not client.service_is_ready(), what="service gone")
    assert not future.done()


async def test_disconnect_fails_pending_ros_callers(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """When the serving client disconnects, its service leaves ROS; callers get no default."""
    ws = await ws_connect()
    await ws.send({"op": "advertise_service", "service": topic, "type": "std_srvs/SetBool"})
    client = ros_node.create_client(SetBool, topic)
    await wait_service(client)
    future = client.call_async(SetBool.Request(data=True))
    await ws.expect(op="call_service", service=topic)
    await ws.close()
    await async_wait_until(lambda: not client.service_is_ready(), what="service gone")
    assert not future.done()


async def test_first_owner_keeps_a_served_service(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """A second client advertising a service another client serves is refused; the first keeps it."""
    first = await ws_connect()
    await first.send({"op": "advertise_service", "service": topic, "type": "std_srvs/SetBool"})
    await roundtrip(first)
    second = await ws_connect()
    await second.send({"op": "advertise_service", "service": topic, "type": "std_srvs/SetBool",
                       "id": "again"})
    refused = await second.expect(op="status", id="again")
    assert refused["level"] == "error" and "already served" in refused["msg"]
    client = ros_node.create_client(SetBool, topic)
    await wait_service(client)
    future = client.call_async(SetBool.Request(data=True))
    request = await first.expect(op="call_service", service=topic)
    await first.send({"op": "service_response", "service": topic, "id": request["id"],
                      "result": True, "values": {"success": True, "message": "first"}})
    assert (await ros_future(future)).message == "first"


async def test_fragmented_call_service(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """A call_service op sent as fragment ops is reassembled and carried out."""
    _mult(ros_node, topic)
    ws = await ws_connect()
    text = json.dumps({"op": "call_service", "service": topic, "type": "mult_msgs/MultFloats",
                       "args": {"x": 1.5, "y": 2.0}, "id": "frag", "timeout": 30})
    pieces = split_fragments(text, 10, "f1")
    assert len(pieces) > 3
    for piece in reversed(pieces):  # any order
        await ws.send_raw(piece)
    reply = await ws.expect(op="service_response", id="frag")
    assert reply["values"] == {"result": 3.0}


async def test_call_service_fragment_size(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """A call_service with fragment_size gets its service_response as fragment ops."""
    _mult(ros_node, topic)
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
    await server.send({"op": "advertise_service", "service": topic, "type": "std_srvs/SetBool"})
    await roundtrip(server)
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
    ws_connect: Any, ros_node: Any, topic: str
) -> None:
    """A service_response not in the usual shape (taken as decoded) gets the generic path's
    error naming what is wrong, and the ROS caller still waits for a good answer."""
    ws = await ws_connect()
    client = await serve_set_bool(ws, ros_node, topic)
    future = client.call_async(SetBool.Request(data=True))
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
    # a bad response (its value does not convert) took the call; the next call is answered
    # with the service named as the client spelled it, without the leading slash
    future = client.call_async(SetBool.Request(data=False))
    request = await ws.expect(op="call_service", service=topic)
    await ws.send({"op": "service_response", "service": topic.lstrip("/"), "id": request["id"],
                   "result": True, "values": {"success": True, "message": "at last"}})
    assert (await ros_future(future)).message == "at last"


async def test_unanswered_ros_callers_are_forgotten_after_the_timeout(
    make_bridge: Any, ws_connect: Any, ros_node: Any, topic: str
) -> None:
    """Each ROS call a client leaves unanswered is forgotten (and logged) once
    --served-call-timeout has passed, one after the other (the second well after the first),
    while the calls it answers in time are answered."""
    bridge = make_bridge("--served-call-timeout", "1")
    ws = await ws_connect(bridge.url)
    client = await serve_set_bool(ws, ros_node, topic)
    first = client.call_async(SetBool.Request(data=True))
    first_id = (await ws.expect(op="call_service", service=topic))["id"]
    answered: list[str] = []
    since = time.monotonic()
    while time.monotonic() - since < 0.1 or len(answered) < 2:  # calls answered in time
        future = client.call_async(SetBool.Request(data=False))
        request = await ws.expect(op="call_service", service=topic)
        await ws.send({"op": "service_response", "service": topic, "id": request["id"],
                       "result": True, "values": {"success": True, "message": "in time"}})
        assert (await ros_future(future)).message == "in time"
        answered.append(request["id"])
    second = client.call_async(SetBool.Request(data=True))
    second_id = (await ws.expect(op="call_service", service=topic))["id"]
    await asyncio.to_thread(bridge.wait_for_line, f"no answer for {first_id} within 1", 10)
    await asyncio.to_thread(bridge.wait_for_line, f"no answer for {second_id} within 1", 10)
    await ws.send({"op": "service_response", "service": topic, "id": first_id,
                   "result": True, "values": {"success": True, "message": "late"}})
    error = await ws.expect(op="status", level="error")
    assert f"no ROS call {first_id!r}" in error["msg"]
    assert not first.done() and not second.done()
    assert not any(f"{rid} within" in line for rid in answered for line in bridge.lines)


async def test_a_call_between_clients_times_out_with_its_own_timeout(
    ws_connect: Any, topic: str
) -> None:
    """A call to a service another client serves fails after the call's own timeout when
    that client does not answer; its late answer then finds no call waiting."""
    server = await ws_connect()
    await server.send({"op": "advertise_service", "service": topic, "type": "std_srvs/SetBool"})
    await roundtrip(server)
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
