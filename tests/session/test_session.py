"""A rosbridge session on its ports alone, in memory: no ROS, no socket.

Each test runs the real :class:`~rosbridge_core.session.session.Session` (its frame loop,
gate, op groups and outbox) over a :class:`~rosbridge_core.memory.link.MemoryLink`, sharing a
:class:`~rosbridge_core.memory.server.MemoryServer`'s state over an in-memory ROS graph whose
other node, the :class:`~tests.session.harness.Robot`, hears, publishes and serves.
"""

from __future__ import annotations

import asyncio
import json
import subprocess
import sys
from pathlib import Path

import cbor2
import pytest

from rosbridge_core.memory.server import MemoryServer
from rosbridge_core.protocol.ops import ACKS_HEADER
from rosbridge_core.security.auth import Principal
from rosbridge_core.security.permissions import Role
from rosbridge_core.session.resume import SentFrames
from tests.helpers import async_wait_until
from tests.session.harness import Client, open_session

ROOT = Path(__file__).resolve().parents[2]


async def test_advertise_and_publish_reach_the_graphs_publisher() -> None:
    """An advertise then a publish put the converted message on the graph's publisher."""
    async with open_session() as (_session, link, robot, bridge):
        heard = robot.hear("/chatter", "std_msgs/msg/String")
        link.feed({"op": "advertise", "topic": "/chatter", "type": "std_msgs/String"})
        link.feed({"op": "publish", "topic": "/chatter", "msg": {"data": "hello"}})
        link.feed({"op": "set_level", "level": "info", "id": "sync"})  # answered in order
        link.feed({"op": "set_level", "level": "bogus", "id": "sync"})
        op = await link.next_op()
        assert op["op"] == "status" and op["id"] == "sync", op  # nothing before it
        assert ("/chatter", "std_msgs/msg/String", False) in bridge.node.publishers
        assert heard == [{"data": "hello"}]


@pytest.mark.parametrize("compression", ["none", "cbor"])
async def test_a_subscriber_gets_what_the_graph_delivers(compression: str) -> None:
    """A subscribe is answered with the messages the graph delivers, as JSON text or as a
    CBOR binary frame as the subscribe asked."""
    async with open_session() as (_session, link, robot, _bridge):
        link.feed({"op": "subscribe", "topic": "/chatter", "type": "std_msgs/msg/String",
                   "compression": compression, "id": "s1"})
        link.feed({"op": "set_level", "level": "bogus", "id": "sync"})
        assert (await link.next_op())["id"] == "sync"  # the subscribe was carried out
        robot.publish("/chatter", "std_msgs/msg/String", {"data": "hi"})
        frame = await link.next_frame()
        if compression == "cbor":
            assert isinstance(frame, bytes)
            op = cbor2.loads(frame)
        else:
            assert isinstance(frame, str)
            op = json.loads(frame)
        assert op == {"op": "publish", "topic": "/chatter", "msg": {"data": "hi"}}


async def test_a_malformed_frame_gets_an_error_and_the_session_goes_on() -> None:
    """A frame that is no JSON, and an op missing its topic, each get a status error naming
    what was wrong; the ops after them are still carried out."""
    async with open_session() as (_session, link, robot, _bridge):
        heard = robot.hear("/n", "std_msgs/msg/Int32")
        link.feed("{not json")
        link.feed({"op": "publish", "msg": {"data": 1}, "id": "p1"})
        link.feed({"op": "advertise", "topic": "/n", "type": "std_msgs/Int32"})
        link.feed({"op": "publish", "topic": "/n", "msg": {"datum": 1}, "id": "p2"})
        link.feed({"op": "publish", "topic": "/n", "msg": {"data": 7}})
        link.feed({"op": "set_level", "level": "bogus", "id": "sync"})
        first = await link.next_op()
        assert first["op"] == "status" and first["level"] == "error", first
        assert "JSON" in first["msg"] or "json" in first["msg"], first
        second = await link.next_op()
        assert second["level"] == "error" and second["id"] == "p1", second
        assert "topic" in second["msg"], second
        third = await link.next_op()
        assert third["id"] == "p2" and "msg.datum" in third["msg"] and "/n" in third["msg"], third
        assert (await link.next_op())["id"] == "sync"
        assert heard == [{"data": 7}]


async def test_a_refused_call_is_answered_as_a_stock_client_waits() -> None:
    """A call_service the role does not allow gets a status error saying it is forbidden and
    the failed service_response (result false, same id) a stock client waits for; an
    allowed one is served."""
    role = Role("viewer", allow={"call_service": ("/open",)})
    principal = Principal("alice", role, b"", b"")
    async with open_session(Client(principal=principal)) as (_session, link, robot, _bridge):
        robot.serve("/open", "std_srvs/srv/Trigger",
                    lambda args: {"success": True, "message": "opened"})
        link.feed({"op": "call_service", "service": "/secret", "id": "c1", "args": {}})
        error = await link.next_op()
        assert error["op"] == "status" and error["level"] == "error", error
        assert "forbidden" in error["msg"] and "/secret" in error["msg"], error
        answer = await link.next_op()
        assert answer["op"] == "service_response" and answer["id"] == "c1", answer
        assert answer["result"] is False
        link.feed({"op": "call_service", "service": "/open", "id": "c2", "args": {}})
        answer = await link.next_op()
        assert answer == {"op": "service_response", "service": "/open", "id": "c2",
                          "result": True, "values": {"success": True, "message": "opened"}
                          }, answer


async def test_a_call_is_answered_and_one_that_times_out_fails_in_time() -> None:
    """A call the graph answers gets its values; one whose server never answers gets a
    failed service_response when the call's own timeout runs out, naming the service."""
    async with open_session() as (_session, link, robot, _bridge):
        robot.serve("/mult", "mult_msgs/srv/MultFloats",
                    lambda args: {"result": args["x"] * args["y"]})
        robot.serve("/stuck", "std_srvs/srv/Trigger", None)
        link.feed({"op": "call_service", "service": "/stuck", "id": "late", "args": {},
                   "timeout": 0.05})
        link.feed({"op": "call_service", "service": "/mult", "id": "now",
                   "args": {"x": 1.5, "y": 2.0}})
        answered = await link.next_op()
        assert answered["id"] == "now" and answered["values"] == {"result": 3.0}, answered
        failed = await link.next_op()
        assert failed["op"] == "service_response" and failed["id"] == "late", failed
        assert failed["result"] is False and "/stuck" in failed["values"], failed


async def test_acknowledgements_follow_the_header() -> None:
    """A client that asked for verdicts (ACKS_HEADER) hears "ok" for an accepted op, read
    from its link's handshake headers."""
    async with open_session(Client(headers={ACKS_HEADER: "1"})) as (_session, link, _r, _b):
        link.feed({"op": "advertise", "topic": "/a", "type": "std_msgs/String", "id": "ad"})
        ok = await link.next_op()
        assert ok["level"] == "info" and ok["id"] == "ad" and ok["msg"].startswith("ok:"), ok


async def test_a_lost_link_parks_the_session_and_a_new_link_resumes_it() -> None:
    """A resumable session whose link is lost (not closed by its client) is kept; resumed
    over a new link it sends again the frames the client did not confirm, then what was
    queued while it was away."""
    async with open_session() as (session, first, robot, bridge):
        token = bridge.resumable.new_token()
        session.token = token
        session.outbox.sent = SentFrames(100, 1 << 20)
        bridge.resumable.register(token, session)
        first.feed({"op": "subscribe", "topic": "/t", "type": "std_msgs/String"})
        first.feed({"op": "set_level", "level": "bogus", "id": "sync"})
        assert (await first.next_op())["id"] == "sync"
        first.hang_up(by_client=False)
        await _until_parked(bridge, token)
        robot.publish("/t", "std_msgs/msg/String", {"data": "while away"})
        assert await bridge.resumable.claim(token, None) is session  # as a handshake does
        bridge.resumable.register(token, session)
        second = Client()
        # the client says it received none: the one frame sent (the status) comes again
        resumed = asyncio.create_task(session.resume(second.link, 0))
        again = await second.next_op()
        assert again["op"] == "status" and again["id"] == "sync", again
        missed = await second.next_op()
        assert missed == {"op": "publish", "topic": "/t", "msg": {"data": "while away"}}
        assert session.link is second.link and not session.parked
        second.hang_up()
        await asyncio.wait_for(resumed, 5.0)


async def _until_parked(bridge: MemoryServer, token: str) -> None:
    await async_wait_until(lambda: token in bridge.resumable.parked, 5.0, "the session parked")


def test_the_session_tests_load_no_ros() -> None:
    """Run in a fresh interpreter, every session test passes without rclpy ever imported."""
    script = (
        "import sys, pytest\n"
        f"code = pytest.main([{str(ROOT / 'tests' / 'session')!r}, '-q', '-p', 'no:cacheprovider',"
        " '-k', 'not load_no_ros'])\n"
        "loaded = sorted(m for m in sys.modules if m.split('.')[0] == 'rclpy')\n"
        "print('RCLPY', loaded)\n"
        "sys.exit(code or (3 if loaded else 0))\n"
    )
    done = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True,
                          text=True, timeout=100)
    assert "RCLPY []" in done.stdout, done.stdout[-3000:] + done.stderr[-2000:]
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-2000:]
