"""Service ops over rclpy: what needs a real ROS graph (a call reaching an rclpy service, its
timeout, an rclpy caller of a service a client serves, the service leaving the ROS graph,
--served-call-timeout on a bridge process). The session's own service behaviour (argument
forms, fragments, owners, calls between clients, answers of the wrong shape) is tested in
memory in tests/session/test_services.py."""

from __future__ import annotations

import asyncio
import threading
import time
from typing import Any

from mult_msgs.srv import MultFloats
from rclpy.callback_groups import ReentrantCallbackGroup
from std_srvs.srv import SetBool

from tests.bridge.support import ros_future, serve_mult, serve_set_bool, wait_service
from tests.helpers import async_wait_until


async def test_call_service_args_object_with_type(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """call_service with an args object and a type reaches an rclpy service and returns its answer."""
    serve_mult(ros_node, topic)
    ws = await ws_connect()
    await ws.send({"op": "call_service", "service": topic, "type": "mult_msgs/srv/MultFloats",
                   "args": {"x": 3.0, "y": 4.5}, "id": "c1", "timeout": 30})
    # as long as the call may take (the service's discovery, a fresh bridge's first call)
    reply = await ws.expect(op="service_response", id="c1", timeout=30)
    assert reply == {"op": "service_response", "service": topic, "result": True,
                     "values": {"result": 13.5}, "id": "c1"}


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

