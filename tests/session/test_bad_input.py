"""Bad input of every kind: the sender is told what was wrong and where; everyone keeps working.

Each test sends one kind of bad input, checks the error reply, then checks that
the same connection still works and that a second client was not disturbed. In memory
(moved from tests/bridge, whose rclpy graph made each check of "still working" wait for
DDS matching): the ROS side is the bench's robot node.
"""

from __future__ import annotations

from typing import Any

from tests.op_peer import error_text, sender_and_bystander, still_working
from tests.session.harness import Robot


async def test_malformed_json(ws_connect: Any, topic: str) -> None:
    """A text frame that is not JSON gets an error naming the position of the fault."""
    ws, other = await sender_and_bystander(ws_connect)
    await ws.send_raw('{"op": "publish", "topic": ')
    msg = await error_text(ws)
    assert "malformed JSON" in msg and "column" in msg
    await still_working(ws, other, topic)


async def test_invalid_binary_frame(ws_connect: Any, topic: str) -> None:
    """A binary frame that is not valid CBOR gets an error saying so."""
    ws, other = await sender_and_bystander(ws_connect)
    await ws.send_raw(b"\xff\xff\x00\x1c")
    msg = await error_text(ws)
    assert "CBOR" in msg
    await still_working(ws, other, topic)


async def test_unknown_op(ws_connect: Any, topic: str) -> None:
    """An unknown op is named in the error, which carries the request id."""
    ws, other = await sender_and_bystander(ws_connect)
    await ws.send({"op": "frobnicate", "id": "u1"})
    msg = await error_text(ws, id="u1")
    assert "unknown op 'frobnicate'" in msg
    await still_working(ws, other, topic)


async def test_missing_field(ws_connect: Any, topic: str) -> None:
    """An op without a required field gets an error naming the op and the field."""
    ws, other = await sender_and_bystander(ws_connect)
    await ws.send({"op": "subscribe", "id": "m1"})
    msg = await error_text(ws, id="m1")
    assert "subscribe" in msg and "'topic'" in msg
    await still_working(ws, other, topic)


async def test_ill_typed_field(ws_connect: Any, topic: str) -> None:
    """A field of the wrong kind is named with what was expected."""
    ws, other = await sender_and_bystander(ws_connect)
    await ws.send({"op": "subscribe", "topic": topic, "throttle_rate": "fast", "id": "i1"})
    msg = await error_text(ws, id="i1")
    assert "throttle_rate" in msg and "milliseconds" in msg
    await still_working(ws, other, topic)


async def test_unknown_type(ws_connect: Any, topic: str) -> None:
    """Advertising a type no installed package provides names the type."""
    ws, other = await sender_and_bystander(ws_connect)
    await ws.send({"op": "advertise", "topic": topic, "type": "no_such_pkg/Thing", "id": "t1"})
    msg = await error_text(ws, id="t1")
    assert "advertise" in msg and "unknown type" in msg and "no_such_pkg/Thing" in msg
    await still_working(ws, other, topic)


async def test_malformed_type_string(ws_connect: Any, topic: str) -> None:
    """A type string of the wrong shape is quoted in the error."""
    ws, other = await sender_and_bystander(ws_connect)
    await ws.send({"op": "advertise", "topic": topic, "type": "std_msgs", "id": "t2"})
    msg = await error_text(ws, id="t2")
    assert "invalid type name 'std_msgs'" in msg
    await still_working(ws, other, topic)


async def test_publish_field_the_type_lacks(ws_connect: Any, topic: str) -> None:
    """A published message with a field its type lacks names the field path."""
    ws, other = await sender_and_bystander(ws_connect)
    await ws.send({"op": "advertise", "topic": topic, "type": "geometry_msgs/Pose"})
    await ws.send({"op": "publish", "topic": topic, "id": "p1",
                   "msg": {"position": {"x": 1.0, "w": 2.0}}})
    msg = await error_text(ws, id="p1")
    assert "msg.position.w" in msg
    await still_working(ws, other, topic)


async def test_publish_wrong_value_kind(ws_connect: Any, topic: str) -> None:
    """A value of the wrong kind names the field path and the expected type."""
    ws, other = await sender_and_bystander(ws_connect)
    await ws.send({"op": "advertise", "topic": topic, "type": "std_msgs/String"})
    await ws.send({"op": "publish", "topic": topic, "id": "p2", "msg": {"data": 5}})
    msg = await error_text(ws, id="p2")
    assert "msg.data" in msg and "string" in msg
    await still_working(ws, other, topic)


async def test_publish_out_of_range_value(ws_connect: Any, topic: str) -> None:
    """An integer outside its field's range names the field path and the type."""
    ws, other = await sender_and_bystander(ws_connect)
    await ws.send({"op": "advertise", "topic": topic, "type": "std_msgs/msg/UInt8"})
    await ws.send({"op": "publish", "topic": topic, "id": "p3", "msg": {"data": 300}})
    msg = await error_text(ws, id="p3")
    assert "msg.data" in msg and "uint8" in msg
    await still_working(ws, other, topic)


async def test_advertise_conflicting_type(ws_connect: Any, robot: Robot, topic: str) -> None:
    """Advertising a topic with another type than the graph's names both types."""
    robot.advertise(topic, "std_msgs/msg/String")
    ws, other = await sender_and_bystander(ws_connect)
    await ws.send({"op": "advertise", "topic": topic, "type": "std_msgs/Int32", "id": "a1"})
    msg = await error_text(ws, id="a1")
    assert "std_msgs/msg/String" in msg and "std_msgs/msg/Int32" in msg and topic in msg
    await still_working(ws, other, topic)


async def test_call_missing_service(ws_connect: Any, topic: str) -> None:
    """A call to a service that does not exist fails with result false naming the service."""
    ws, other = await sender_and_bystander(ws_connect)
    await ws.send({"op": "call_service", "service": topic, "id": "c1"})
    reply = await ws.expect(op="service_response", id="c1")
    assert reply["result"] is False
    assert topic in reply["values"] and "does not exist" in reply["values"]
    await still_working(ws, other, topic)


async def test_service_timeout(ws_connect: Any, robot: Robot, topic: str) -> None:
    """A service that never answers fails after the timeout, saying how long was waited."""
    robot.serve(topic, "std_srvs/srv/SetBool", None)
    ws, other = await sender_and_bystander(ws_connect)
    await ws.send({"op": "call_service", "service": topic, "type": "std_srvs/SetBool",
                   "args": {"data": True}, "timeout": 0.3, "id": "c2"})
    reply = await ws.expect(op="service_response", id="c2")
    await still_working(ws, other, topic)
    assert reply["result"] is False and "timed out after 0.3 s" in reply["values"]


async def test_subscribe_unknown_type(ws_connect: Any, topic: str) -> None:
    """A subscribe that cannot be made (unknown type) is answered with an error and its id."""
    ws, other = await sender_and_bystander(ws_connect)
    await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/NoSuchThing", "id": "s1"})
    msg = await error_text(ws, id="s1")
    assert "subscribe" in msg and "std_msgs/NoSuchThing" in msg
    await still_working(ws, other, topic)


async def test_fragment_bad_num_total(ws_connect: Any, topic: str) -> None:
    """A fragment whose num is not below total names both fields."""
    ws, other = await sender_and_bystander(ws_connect)
    await ws.send({"op": "fragment", "id": "f1", "data": "{}", "num": 5, "total": 2})
    msg = await error_text(ws, id="f1")
    assert "'num'" in msg and "'total'" in msg
    await still_working(ws, other, topic)
