"""The bridge's Session served in memory (MemoryServer, MemoryLink): frames in, frames out,
no socket and no ROS, with what the client owned released when its link ends."""

from __future__ import annotations

import asyncio
import json
from typing import Any

from rosbridge_core.memory.server import MemoryServer


def _ops(frames: list[str | bytes]) -> list[dict[str, Any]]:
    return [json.loads(f) for f in frames]


async def test_frames_in_answers_out_in_the_same_call() -> None:
    """A client's frames reach the session in its call, and what the session answers at once
    (its verdicts, a message to the client's own subscription, a refusal naming the field)
    comes back before the call returns."""
    server = MemoryServer()
    out: list[str | bytes] = []
    conn = server.connect(out.append, headers={"X-Rosbridge-Acks": "1"})
    conn.send(json.dumps({"op": "advertise", "id": "a", "topic": "/t",
                          "type": "std_msgs/msg/Int32"}))
    conn.send(json.dumps({"op": "subscribe", "id": "s", "topic": "/t",
                          "type": "std_msgs/msg/Int32"}))
    conn.send(json.dumps({"op": "publish", "topic": "/t", "msg": {"data": 7}}))
    conn.send(json.dumps({"op": "publish", "id": "p", "topic": "/t", "msg": {"data": "x"}}))
    got = _ops(out)
    assert got[:2] == [
        {"op": "status", "level": "info", "msg": "ok: advertise /t", "id": "a"},
        {"op": "status", "level": "info", "msg": "ok: subscribe /t", "id": "s"}]
    assert {"op": "publish", "topic": "/t", "msg": {"data": 7}} in got
    refusal = got[-1]
    assert refusal["op"] == "status" and refusal["level"] == "error" and refusal["id"] == "p"
    assert "data" in refusal["msg"] and "int32" in refusal["msg"]
    await server.close()


async def test_a_dropped_link_releases_what_the_client_owned() -> None:
    """When the link drops, the session ends and its publisher, subscription and served
    service leave the graph."""
    server = MemoryServer()
    conn = server.connect(lambda frame: None)
    for op in ({"op": "advertise", "topic": "/t", "type": "std_msgs/msg/Int32"},
               {"op": "subscribe", "topic": "/u", "type": "std_msgs/msg/Int32"},
               {"op": "advertise_service", "service": "/s", "type": "std_srvs/srv/Trigger"}):
        conn.send(json.dumps(op))
    graph = server.node
    assert graph.publishers and graph.subscriptions and graph.server_count("/s") == 1
    conn.drop()
    await asyncio.wait_for(conn.ended(), 5)
    assert not graph.publishers and not graph.subscriptions and graph.server_count("/s") == 0
    assert not server.sessions
    await server.close()
