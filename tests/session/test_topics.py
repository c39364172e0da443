"""Topic ops of a session, in memory (moved from tests/bridge/test_ops_topics.py, which keeps
what needs rclpy): type spellings, throttling, fragments, CBOR, merged subscriptions,
unsubscribing, the legacy png compression and relative names.

The publisher on the ROS side is the bench's robot node; a subscribe is in place once a
:func:`~tests.op_peer.roundtrip` after it is answered (no waiting for DDS matching).
"""

from __future__ import annotations

import json
import struct
from typing import Any

from tests.op_peer import OpPeer, rosapi, roundtrip
from tests.session.harness import Robot


async def _subscribe(ws: OpPeer, topic: str, type_name: str, **options: Any) -> None:
    await ws.send({"op": "subscribe", "topic": topic, "type": type_name, **options})
    await roundtrip(ws, "subscribed")


async def _subscribers(ws: OpPeer, topic: str) -> list[str]:
    return list((await rosapi(ws, "/rosapi/subscribers", {"topic": topic}))["subscribers"])


async def test_both_type_spellings(ws_connect: Any, topic: str) -> None:
    """``std_msgs/String`` and ``std_msgs/msg/String`` name the same type on advertise and subscribe."""
    ws = await ws_connect()
    await ws.send({"op": "advertise", "topic": topic, "type": "std_msgs/String"})
    await _subscribe(ws, topic, "std_msgs/msg/String")
    other = await ws_connect()
    await _subscribe(other, topic, "std_msgs/String")
    await ws.send({"op": "publish", "topic": topic, "msg": {"data": "m"}})
    assert (await ws.expect(op="publish", topic=topic))["msg"] == {"data": "m"}
    assert (await other.expect(op="publish", topic=topic))["msg"] == {"data": "m"}
    statuses = [o for o in ws.backlog + other.backlog if o.get("op") == "status"]
    assert statuses == []


async def test_throttle_rate_keeps_latest(ws_connect: Any, robot: Robot, topic: str) -> None:
    """With throttle_rate, a burst is thinned out and its last message still arrives."""
    ws = await ws_connect()
    await _subscribe(ws, topic, "std_msgs/String", throttle_rate=300)
    for i in range(20):
        robot.publish(topic, "std_msgs/msg/String", {"data": str(i)})
    seen: list[Any] = []
    while not seen or seen[-1] != "19":
        seen.append((await ws.expect(op="publish", topic=topic))["msg"]["data"])
    assert len(seen) < 20
    assert seen[0] == "0"


async def test_fragment_size_splits_outgoing(ws_connect: Any, robot: Robot, topic: str) -> None:
    """With fragment_size, a large publish arrives as fragment ops that reassemble into it; a
    size under the bridge's floor (1,024 bytes) is raised to it, with a warning saying so."""
    ws = await ws_connect()
    await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/String",
                   "fragment_size": 16, "id": "s"})
    warning = await ws.expect(op="status", id="s")
    assert warning["level"] == "warning" and "fragment_size 16" in warning["msg"]
    assert "1024" in warning["msg"]
    data = "abcdefghij" * 500
    robot.publish(topic, "std_msgs/msg/String", {"data": data})
    first = await ws.expect(op="fragment")
    pieces = {first["num"]: first["data"]}
    assert first["total"] == -(-len(json.dumps({"op": "publish", "topic": topic,
                                                "msg": {"data": data}})) // 1024)
    while len(pieces) < first["total"]:
        frag = await ws.expect(op="fragment", id=first["id"])
        assert len(frag["data"]) <= 1024
        pieces[frag["num"]] = frag["data"]
    text = "".join(pieces[i] for i in range(first["total"]))
    assert json.loads(text) == {"op": "publish", "topic": topic, "msg": {"data": data}}


async def test_compression_cbor(ws_connect: Any, robot: Robot, topic: str) -> None:
    """compression=cbor sends a binary CBOR publish op; int32[] is a typed array (tag 78)."""
    ws = await ws_connect()
    await _subscribe(ws, topic, "std_msgs/Int32MultiArray", compression="cbor")
    robot.publish(topic, "std_msgs/msg/Int32MultiArray", {"data": [1, -2, 300000]})
    op = await ws.expect(op="publish", topic=topic)
    data = op["msg"]["data"]
    assert data.tag == 78
    assert list(struct.unpack("<3i", data.value)) == [1, -2, 300000]


async def test_compression_cbor_uint8_as_bytes(ws_connect: Any, robot: Robot, topic: str) -> None:
    """compression=cbor carries uint8[] as a CBOR byte string."""
    ws = await ws_connect()
    await _subscribe(ws, topic, "std_msgs/msg/UInt8MultiArray", compression="cbor")
    robot.publish(topic, "std_msgs/msg/UInt8MultiArray", {"data": [0, 1, 255]})
    op = await ws.expect(op="publish", topic=topic)
    assert op["msg"]["data"] == b"\x00\x01\xff"


async def test_merged_subscriptions_deliver_once(ws_connect: Any, robot: Robot, topic: str) -> None:
    """Several ids on one topic merge: each message arrives once; each id unsubscribes alone."""
    ws = await ws_connect()
    for sid in ("a", "b", "c"):
        await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/String", "id": sid})
    await roundtrip(ws)
    robot.publish(topic, "std_msgs/msg/String", {"data": "one"})
    robot.publish(topic, "std_msgs/msg/String", {"data": "two"})
    assert (await ws.expect(op="publish"))["msg"]["data"] == "one"
    assert (await ws.expect(op="publish"))["msg"]["data"] == "two"
    await ws.send({"op": "unsubscribe", "topic": topic, "id": "a"})
    await ws.send({"op": "unsubscribe", "topic": topic, "id": "b"})
    await roundtrip(ws)
    robot.publish(topic, "std_msgs/msg/String", {"data": "three"})
    assert (await ws.expect(op="publish"))["msg"]["data"] == "three"
    assert [o for o in ws.backlog if o.get("op") == "publish"] == []  # once, not per id
    await ws.send({"op": "unsubscribe", "topic": topic, "id": "c"})
    assert await _subscribers(ws, topic) == []


async def test_unsubscribe_without_id_removes_all(ws_connect: Any, topic: str) -> None:
    """An unsubscribe without id ends every subscription of that client to the topic."""
    ws = await ws_connect()
    await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/String", "id": 1})
    await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/String", "id": 2})
    assert await _subscribers(ws, topic) == ["/rosbridge"]
    await ws.send({"op": "unsubscribe", "topic": topic})
    assert await _subscribers(ws, topic) == []
    assert [o for o in ws.backlog if o.get("op") == "status"] == []


async def test_png_compression_falls_back_to_json(ws_connect: Any, robot: Robot, topic: str) -> None:
    """compression=png (legacy, offered by stock clients) subscribes with plain JSON and a warning."""
    ws = await ws_connect()
    await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/String",
                   "compression": "png", "id": "png"})
    note = await ws.expect(op="status", level="warning", id="png")
    assert "png" in note["msg"]
    robot.publish(topic, "std_msgs/msg/String", {"data": "plain"})
    op = await ws.expect(op="publish", topic=topic)
    assert op["msg"] == {"data": "plain"}


async def test_relative_names_are_echoed(ws_connect: Any, robot: Robot, topic: str) -> None:
    """A name without the leading slash means the absolute one, and replies use the client's spelling."""
    ws = await ws_connect()
    relative = topic.lstrip("/")
    await _subscribe(ws, relative, "std_msgs/String")
    robot.publish(topic, "std_msgs/msg/String", {"data": "rel"})
    op = await ws.expect(op="publish")
    assert op == {"op": "publish", "topic": relative, "msg": {"data": "rel"}}
    await ws.send({"op": "call_service", "service": "rosapi/get_ros_version", "id": "r"})
    reply = await ws.expect(op="service_response", id="r")
    assert reply["service"] == "rosapi/get_ros_version" and reply["result"] is True
