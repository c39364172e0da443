"""The relay against the wire contract (bridge_server/zenoh/keys.py) alone: a robot played by a
plain Zenoh session of this test, with no ROS at all, puts what an exporter would."""

from __future__ import annotations

import json
import threading
from collections.abc import AsyncIterator
from typing import Any

import pytest
import zenoh

from bridge_server.zenoh import keys
from bridge_server.zenoh.keys import Meta, Snapshot
from bridge_server.zenoh.link import ZenohOptions, open_session
from msgs import cdr
from msgs.std_msgs.msg import String
from tests.helpers import open_wire
from tests.relay.support import free_port, relay_reaches, robot_reachable, start_relay, until

pytestmark = pytest.mark.timeout(60)

ROBOT = "played"


@pytest.fixture
async def played() -> AsyncIterator[tuple[Any, zenoh.Session]]:
    """A relay (the router) and a Zenoh session that plays robot ``played``: alive, and a
    snapshot with one topic."""
    router = f"tcp/127.0.0.1:{free_port()}"
    relay = await start_relay(listen=router)
    robot = await open_session(ZenohOptions(connect=[router]))
    snap = Snapshot(node="played_bridge", topics=[("/chatter", ["std_msgs/msg/String"])])

    def answer(query: zenoh.Query) -> None:
        query.reply(query.key_expr, snap.encode())
        query.drop()  # type: ignore[no-untyped-call]

    held: list[Any] = [robot.declare_queryable(f"{ROBOT}/{keys.GRAPH}", answer),
            robot.liveliness().declare_token(f"{ROBOT}/{keys.ALIVE}")]
    try:
        await robot_reachable(relay, ROBOT)
        yield relay, robot
    finally:
        await relay.close()
        for entity in held:
            entity.undeclare()
        robot.close()  # type: ignore[no-untyped-call]


async def _subscribe(relay: Any, robot: zenoh.Session, ws: Any) -> None:
    """Subscribe the client to /chatter and wait for the relay's demand token (declared after
    its Zenoh subscriber, so what the robot puts from then on reaches it)."""
    seen: list[str] = []
    watcher = robot.liveliness().declare_subscriber(
        f"{ROBOT}/{keys.DEMAND}/{relay.relay_id}/chatter",
        lambda s: seen.append(str(s.kind)), history=True)
    try:
        await ws.send({"op": "subscribe", "topic": "/chatter"})
        await until(lambda: "SampleKind.PUT" in seen, "the relay's demand token")
    finally:
        watcher.undeclare()  # type: ignore[no-untyped-call]


async def test_each_message_reaches_a_client_once(played: tuple[Any, zenoh.Session]) -> None:
    """The same message put twice (the latched reply and the put of one message carry the
    same epoch and number) reaches the client once; the next number, and a new epoch (the
    robot's exporter restarted, counting from 1 again), each get through."""
    relay, robot = played
    ws = await open_wire(f"ws://127.0.0.1:{relay.port}/{ROBOT}")
    try:
        await _subscribe(relay, robot, ws)

        def put(text: str, seq: int, epoch: str = "e1") -> None:
            meta = Meta(type="std_msgs/msg/String", stamp_ns=1, epoch=epoch, seq=seq)
            robot.put(f"{ROBOT}/chatter", cdr.encode(String(data=text)),
                      attachment=meta.encode())

        put("one", 1)
        put("one again", 1)
        put("two", 2)
        put("restarted", 1, epoch="e2")
        got = [(await ws.expect(op="publish", topic="/chatter"))["msg"]["data"]
               for _ in range(3)]
        assert got == ["one", "two", "restarted"]
        with pytest.raises(AssertionError):
            await ws.expect(op="publish", topic="/chatter", timeout=0.5)
    finally:
        await ws.close()


async def test_a_latched_message_larger_than_the_replies_bound_reaches_a_late_viewer(
        played: tuple[Any, zenoh.Session]) -> None:
    """A latched message of 20 MiB (a large map: under the relay's 32 MiB for a message,
    over the 16 MiB its queue of replies and requests holds, and over what a new
    subscription holds until the robot's answer ends) is the robot's answer to the relay's
    late subscription, and reaches the viewer whole. The robot ends its answer a moment
    after the message, so the relay holds the message first."""
    relay, robot = played
    text = "m" * (20 * 1024 * 1024)
    latched = cdr.encode(String(data=text))
    meta = Meta(type="std_msgs/msg/String", latched=True, stamp_ns=1, epoch="l", seq=1)

    def answer(query: zenoh.Query) -> None:
        query.reply(query.key_expr, latched, attachment=meta.encode())
        threading.Timer(0.5, query.drop).start()  # a robot slow to end its answer

    queryable = robot.declare_queryable(f"{ROBOT}/{keys.LATCHED}/**", answer)
    ws = await open_wire(f"ws://127.0.0.1:{relay.port}/{ROBOT}")
    try:
        await ws.send({"op": "subscribe", "topic": "/chatter"})
        op = await ws.expect(op="publish", topic="/chatter", timeout=30)
        assert len(op["msg"]["data"]) == len(text)
    finally:
        await ws.close()
        queryable.undeclare()  # type: ignore[no-untyped-call]


async def test_a_message_without_its_type_is_dropped_and_said(
        played: tuple[Any, zenoh.Session], caplog: pytest.LogCaptureFixture) -> None:
    """A put whose attachment is not a Meta object is not delivered; the relay's log says why
    (once), and the next good message gets through."""
    relay, robot = played
    ws = await open_wire(f"ws://127.0.0.1:{relay.port}/{ROBOT}")
    try:
        await _subscribe(relay, robot, ws)
        robot.put(f"{ROBOT}/chatter", b"\x00\x01\x00\x00", attachment=b"not json")
        good = Meta(type="std_msgs/msg/String", epoch="e", seq=1).encode()
        robot.put(f"{ROBOT}/chatter", cdr.encode(String(data="fine")), attachment=good)
        op = await ws.expect(op="publish", topic="/chatter")
        assert op["msg"] == {"data": "fine"}
        assert any("is not a Meta object" in r.getMessage() for r in caplog.records)
    finally:
        await ws.close()


async def test_a_snapshot_of_the_wrong_shape_is_refused_and_said(
        played: tuple[Any, zenoh.Session], caplog: pytest.LogCaptureFixture) -> None:
    """A graph snapshot whose fields do not have their shapes (``served`` a list, a node
    without its lists) is refused with the field named (logged once, then counted for the
    relay's page), and the relay goes on with the last
    good one: a client's advertise_service and the rosapi topic list work; a field the relay
    does not know (a newer robot's) is left out."""
    relay, robot = played
    ws = await open_wire(f"ws://127.0.0.1:{relay.port}/{ROBOT}")
    try:
        graph = relay.robots[ROBOT].graph
        good = Snapshot(node="played_bridge", topics=[("/chatter", ["std_msgs/msg/String"])])
        for n, (bad, named) in enumerate((
                (b'{"served": []}', "served is not an object"),
                (b'{"nodes": {"/n": {"name": "n"}}}', "nodes./n is not an object with name, "
                 "namespace, subscribes, publishes, serves")), 1):
            robot.put(f"{ROBOT}/{keys.GRAPH}", bad)
            await until(lambda n=n: graph.faults.counts.get("bad_graph") == n,
                        f"the relay to refuse a snapshot whose {named}")
            assert f"is not a Snapshot ({named})" in graph.faults.last["bad_graph"]
        # logged once, naming the first (the second is counted)
        assert [r.getMessage() for r in caplog.records if "is not a Snapshot" in r.getMessage()
                ] == [f"robot {ROBOT}: a graph document dropped: a robot's @graph payload is "
                      "not a Snapshot (served is not an object) (bad_graph: 1 so far; counted "
                      "on the relay's page, not logged each time)"]
        assert graph.snapshot == good
        await ws.send({"op": "advertise_service", "service": "/served_here",
                       "type": "std_srvs/srv/Trigger"})
        await ws.send({"op": "call_service", "service": "/rosapi/topics", "id": "t"})
        reply = await ws.expect(op="service_response", id="t")
        assert reply["result"] is True and reply["values"]["topics"] == ["/chatter"], reply

        newer = json.loads(good.encode()) | {"cameras": ["front"]}
        newer["node"] = "newer_bridge"
        robot.put(f"{ROBOT}/{keys.GRAPH}", json.dumps(newer).encode())
        await until(lambda: graph.snapshot.node == "newer_bridge", "the newer robot's snapshot")
    finally:
        await ws.close()


async def test_a_robots_parameter_answers_are_read_or_refused_by_name(
        played: tuple[Any, zenoh.Session]) -> None:
    """A get answer flagged binary is read as the byte array (rosapi's get_param gives its
    numbers, as on the robot's own bridge); one that is not [is set, value], or whose binary
    value is not base64 text, is refused with what is wrong named."""
    relay, robot = played
    answers = {"good": b'[true, "aGk=", true]', "shape": b'{"set": true}',
               "b64": b'[true, "not base64!", true]'}

    def answer(query: zenoh.Query) -> None:
        name = json.loads(query.payload.to_bytes() if query.payload else b"{}").get("name")
        query.reply(query.key_expr, answers[name])
        query.drop()  # type: ignore[no-untyped-call]

    queryable = robot.declare_queryable(f"{ROBOT}/{keys.PARAM}/some_node", answer)
    await relay_reaches(relay, f"{ROBOT}/{keys.PARAM}/some_node")
    ws = await open_wire(f"ws://127.0.0.1:{relay.port}/{ROBOT}")
    try:
        said = {}
        for name in answers:
            await ws.send({"op": "call_service", "service": "/rosapi/get_param", "id": name,
                           "args": {"name": f"/some_node:{name}"}})
            said[name] = (await ws.expect(op="service_response", id=name))["values"]
        assert said["good"]["value"] == "[104, 105]", said
        assert "the answer to a parameter get is not [is set, value]" in said["shape"], said
        assert "the answer to a parameter get's binary value is not base64 text" in \
            said["b64"], said
    finally:
        await ws.close()
        queryable.undeclare()  # type: ignore[no-untyped-call]


def test_a_messages_attachment_is_the_same_json_as_before() -> None:
    """A ``Meta`` is made for every message a robot puts, from its fields (not ``asdict``):
    the bytes are the compact JSON object a robot of the last release sent, field for field,
    and decode back to the same ``Meta``."""
    meta = Meta(type="sensor_msgs/msg/Imu", latched=True, stamp_ns=1_764_300_000_123_456_789,
                epoch="e\u00e9\"1", seq=42)
    data = meta.encode()
    assert data == (b'{"type":"sensor_msgs/msg/Imu","latched":true,'
                    b'"stamp_ns":1764300000123456789,"epoch":"e\\u00e9\\"1","seq":42}')
    assert data == json.dumps({"type": meta.type, "latched": True, "stamp_ns": meta.stamp_ns,
                               "epoch": meta.epoch, "seq": 42},
                              separators=(",", ":")).encode()
    assert Meta.decode(data) == meta
