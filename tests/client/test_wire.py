"""The client over a real loopback websocket, against a scripted rosbridge peer (no ROS)."""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator
from typing import Any

import pytest

import roslibpy_lite
from msgs.mult_msgs.srv import MultFloats
from msgs.std_msgs.msg import Int16, String
from roslibpy_lite import (
    Client,
    ConnectError,
    ConnectionClosed,
    ConnectionState,
    Disconnected,
    InvalidMessageError,
    RosTimeoutError,
    ServiceError,
    StatusError,
    UsageError,
)
from tests.client.support import ScriptedPeer, fast_backoff

MULT = "mult_msgs/srv/MultFloats"


@pytest.fixture
async def peer() -> AsyncIterator[ScriptedPeer]:
    """A listening scripted peer, stopped after the test."""
    p = await ScriptedPeer().start()
    yield p
    await p.stop()


@pytest.fixture
async def ros(peer: ScriptedPeer) -> AsyncIterator[Client]:
    """A client connected to the scripted peer, with fast reconnects."""
    async with roslibpy_lite.connect(peer.url, backoff=fast_backoff()) as client:
        yield client


async def test_connect_is_awaitable_and_a_context_manager(peer: ScriptedPeer) -> None:
    """``await connect()`` and ``async with connect()`` both give a connected client."""
    client = await roslibpy_lite.connect(peer.url)
    assert client.is_connected
    await client.close()
    assert client.state is ConnectionState.CLOSED
    async with roslibpy_lite.connect(peer.url) as ros:
        assert ros.is_connected
    assert ros.state is ConnectionState.CLOSED


async def test_connect_to_nothing_raises_connect_error(peer: ScriptedPeer) -> None:
    """Nobody listening: connect raises ConnectError (after retrying until open_timeout)."""
    url = peer.url
    await peer.stop()
    with pytest.raises(ConnectError, match="cannot connect"):
        await roslibpy_lite.connect(url, reconnect=False)
    with pytest.raises(ConnectError):
        await roslibpy_lite.connect(url, open_timeout=0.2, backoff=fast_backoff())


async def test_topic_ops_on_the_wire(ros: Client, peer: ScriptedPeer) -> None:
    """advertise, publish, subscribe (with options), unsubscribe, unadvertise go out as rosbridge ops."""
    pub = await ros.advertise("/chatter", "std_msgs/String", latch=True)
    await pub.publish({"data": "hi"})
    sub = await ros.subscribe("/imu", "sensor_msgs/msg/Imu", throttle_rate=50, queue_length=2,
                              compression="cbor", fragment_size=500)
    await sub.unsubscribe()
    await pub.unadvertise()
    adv = await peer.expect(op="advertise", topic="/chatter")
    assert adv["type"] == "std_msgs/msg/String" and adv["latch"] is True and adv["id"] == pub.id
    await peer.expect(op="publish", topic="/chatter", msg={"data": "hi"})
    s = await peer.expect(op="subscribe", topic="/imu")
    assert (s["type"], s["throttle_rate"], s["queue_length"], s["compression"], s["id"]) == (
        "sensor_msgs/msg/Imu", 50, 2, "cbor", sub.id)
    assert s["fragment_size"] == 500
    await peer.expect(op="unsubscribe", topic="/imu", id=sub.id)
    await peer.expect(op="unadvertise", topic="/chatter")
    ops = [op["op"] for op in peer.received]
    assert ops == ["advertise", "publish", "subscribe", "unsubscribe", "unadvertise"]


async def test_typed_publish_checks_type_and_fields(ros: Client, peer: ScriptedPeer) -> None:
    """A typed publisher sends instances in wire form and refuses other types or bad fields."""
    pub = await ros.advertise("/n", Int16)
    await pub.publish(Int16(data=7))
    await peer.expect(op="publish", topic="/n", msg={"data": 7})
    with pytest.raises(UsageError, match="std_msgs/msg/Int16"):
        await pub.publish(String(data="x"))  # type: ignore[arg-type]
    bad = Int16()
    bad.data = 70000  # reassigned after it was built (construction would refuse it)
    with pytest.raises(InvalidMessageError, match="data") as info:
        await pub.publish(bad)
    assert info.value.path == "data"
    untyped = await ros.advertise("/m", "std_msgs/msg/String")
    with pytest.raises(UsageError, match="expected a std_msgs/msg/String"):
        await untyped.publish(Int16(data=1))  # type: ignore[arg-type]


async def test_two_publishers_share_one_advertise(ros: Client, peer: ScriptedPeer) -> None:
    """Two handles on one topic advertise once and unadvertise only when both are closed."""
    a = await ros.advertise("/shared", "std_msgs/msg/String")
    b = await ros.advertise("/shared", "std_msgs/msg/String")
    with pytest.raises(UsageError, match="already advertised"):
        ros.advertise("/shared", "std_msgs/msg/Int16")
    await a.unadvertise()
    await b.publish({"data": "still"})
    await peer.expect(op="publish", msg={"data": "still"})
    assert peer.count(op="unadvertise") == 0
    await b.unadvertise()
    await peer.expect(op="unadvertise", topic="/shared")
    assert peer.count(op="advertise") == 1


async def test_closed_handles_refuse_use(ros: Client) -> None:
    """A closed publisher raises UsageError; closing twice is harmless."""
    async with ros.advertise("/c", "std_msgs/msg/String") as pub:
        pass
    await pub.close()
    with pytest.raises(UsageError, match="closed"):
        await pub.publish({"data": "x"})


async def test_call_service_round_trip(ros: Client, peer: ScriptedPeer) -> None:
    """call_service sends call_service with an id and returns the matching response's values."""
    peer.auto["call_service"] = lambda op: {
        "op": "service_response", "service": op["service"], "id": op["id"], "result": True,
        "values": {"result": op["args"]["x"] * op["args"]["y"]},
    }
    assert await ros.call_service("/mult", MULT, {"x": 2.5, "y": 4.0}, timeout=5) == {"result": 10.0}
    typed = await ros.call_service("/mult", MultFloats, MultFloats.Request(x=3.0, y=2.0))
    assert isinstance(typed, MultFloats.Response) and typed.result == 6.0
    sent = await peer.expect(op="call_service", service="/mult")
    assert sent["type"] == MULT and sent["timeout"] == 6.0


async def test_call_service_failure_raises_service_error(ros: Client, peer: ScriptedPeer) -> None:
    """``result: false`` raises ServiceError carrying the reason text."""
    peer.auto["call_service"] = lambda op: {
        "op": "service_response", "service": op["service"], "id": op["id"], "result": False,
        "values": "service /x does not exist",
    }
    with pytest.raises(ServiceError, match="does not exist") as info:
        await ros.call_service("/x", MULT, {})
    assert info.value.service == "/x"


async def test_status_error_fails_the_call_at_once(ros: Client, peer: ScriptedPeer) -> None:
    """A status error naming the call's id fails it with StatusError (no waiting for the timeout)."""
    peer.auto["call_service"] = lambda op: {
        "op": "status", "level": "error", "msg": "call_service: unknown type", "id": op["id"],
    }
    with pytest.raises(StatusError, match="unknown type"):
        await ros.call_service("/x", MULT, {}, timeout=30)


async def test_call_without_answer_times_out(ros: Client) -> None:
    """No answer within the timeout raises RosTimeoutError (also a TimeoutError)."""
    with pytest.raises(RosTimeoutError, match="/silent"):
        await ros.call_service("/silent", MULT, {}, timeout=0.1)
    with pytest.raises(TimeoutError):
        await ros.call_service("/silent", MULT, {}, timeout=0.1)
    assert not [p for p in ros._host._pending.values() if p.future is not None]


async def _serve_request(peer: ScriptedPeer, service: str, args: Any, rid: str) -> dict[str, Any]:
    await peer.send({"op": "call_service", "service": service, "args": args, "id": rid})
    return await peer.expect(op="service_response", id=rid)


async def test_served_service_sync_and_async_handlers(ros: Client, peer: ScriptedPeer) -> None:
    """Requests from the bridge reach sync and async handlers and are answered with their ids."""

    async def slow(req: Any) -> dict[str, float]:
        await asyncio.sleep(0)
        return {"result": req["x"] + req["y"]}

    await ros.advertise_service("/sync", MULT, lambda req: {"result": req["x"] * req["y"]})
    await ros.advertise_service("/async", MULT, slow)
    await peer.expect(op="advertise_service", service="/sync", type=MULT)
    r1 = await _serve_request(peer, "/sync", {"x": 2.0, "y": 3.0}, "service_request:/sync:1")
    r2 = await _serve_request(peer, "/async", {"x": 2.0, "y": 3.0}, "service_request:/async:1")
    assert (r1["result"], r1["values"], r1["service"]) == (True, {"result": 6.0}, "/sync")
    assert (r2["result"], r2["values"]) == (True, {"result": 5.0})


async def test_typed_handler_gets_request_instance(ros: Client, peer: ScriptedPeer) -> None:
    """A typed service's handler receives a Request instance and may return a Response."""
    seen: list[Any] = []

    def handler(req: Any) -> Any:
        seen.append(req)
        return MultFloats.Response(result=req.x * req.y)

    await ros.advertise_service("/typed", MultFloats, handler)
    reply = await _serve_request(peer, "/typed", {"x": 1.5, "y": 2.0}, "r1")
    assert isinstance(seen[0], MultFloats.Request)
    assert reply["result"] is True and reply["values"] == {"result": 3.0}
    bad = await _serve_request(peer, "/typed", {"x": "text"}, "r2")
    assert bad["result"] is False and "x" in bad["values"]


async def test_raising_handler_answers_result_false_with_its_text(
    ros: Client, peer: ScriptedPeer
) -> None:
    """A handler that raises answers ``result: false`` with the error's text."""

    def handler(req: Any) -> Any:
        raise ValueError("cannot multiply today")

    async def ahandler(req: Any) -> Any:
        raise RuntimeError("async trouble")

    server = await ros.advertise_service("/bad", MULT, handler)
    await ros.advertise_service("/abad", MULT, ahandler)
    reply = await _serve_request(peer, "/bad", {"x": 1.0, "y": 1.0}, "b1")
    assert reply["result"] is False and reply["values"] == "cannot multiply today"
    reply = await _serve_request(peer, "/abad", {}, "b2")
    assert reply["result"] is False and reply["values"] == "async trouble"
    assert server.failures == 1


async def test_unadvertised_service_is_not_answered_by_handler(ros: Client, peer: ScriptedPeer) -> None:
    """After unadvertise_service the op goes out and requests get result false."""
    calls: list[Any] = []
    async with ros.advertise_service("/gone", MULT, calls.append):
        pass
    await peer.expect(op="unadvertise_service", service="/gone")
    reply = await _serve_request(peer, "/gone", {}, "g1")
    assert reply["result"] is False and calls == []
    with pytest.raises(UsageError, match="already served"):
        ros.advertise_service("/dup", MULT, calls.append)
        ros.advertise_service("/dup", MULT, calls.append)


async def test_messages_from_the_peer_reach_the_subscription(ros: Client, peer: ScriptedPeer) -> None:
    """A publish sent by the peer arrives at the subscription over the socket."""
    async with ros.subscribe("/in", "std_msgs/msg/String") as sub:
        await peer.expect(op="subscribe", topic="/in")
        await peer.send({"op": "publish", "topic": "/in", "msg": {"data": "a"}})
        assert await sub.get(5) == {"data": "a"}
    await peer.expect(op="unsubscribe", topic="/in")


# --- connection state and reconnects ------------------------------------------------------------

async def test_drop_reconnects_and_restores_everything(ros: Client, peer: ScriptedPeer) -> None:
    """After a drop the client reconnects and re-sends advertise, subscribe and advertise_service."""
    async with ros.state_changes() as changes:
        pub = await ros.advertise("/p", "std_msgs/msg/String", latch=True)
        sub = await ros.subscribe("/s", "std_msgs/msg/String", throttle_rate=10, queue_length=3)
        await ros.advertise_service("/srv", MULT, lambda req: {"result": 1.0})
        await peer.expect(op="advertise_service")
        mark = len(peer.received)
        await peer.drop()
        assert await changes.next(5) is ConnectionState.RECONNECTING
        assert await changes.next(5) is ConnectionState.CONNECTED
    await peer.wait_connections(2)
    adv = await peer.expect(op="advertise", start=mark, topic="/p")
    assert adv["latch"] is True and adv["type"] == "std_msgs/msg/String"
    s = await peer.expect(op="subscribe", start=mark, topic="/s")
    assert (s["throttle_rate"], s["queue_length"], s["id"]) == (10, 3, sub.id)
    await peer.expect(op="advertise_service", start=mark, service="/srv")
    await peer.send({"op": "publish", "topic": "/s", "msg": {"data": "again"}})
    assert await sub.get(5) == {"data": "again"}
    await pub.publish({"data": "after"})
    await peer.expect(op="publish", start=mark, msg={"data": "after"})
    assert ros.connects == 2


async def test_in_flight_call_fails_with_disconnected(ros: Client, peer: ScriptedPeer) -> None:
    """A call waiting for its answer fails at once with Disconnected when the connection drops."""
    call = asyncio.create_task(ros.call_service("/slow", MULT, {}, timeout=60))
    await peer.expect(op="call_service", service="/slow")
    await peer.drop()
    with pytest.raises(Disconnected, match="/slow"):
        await asyncio.wait_for(call, 10)


async def test_publishes_while_down_are_buffered_and_flushed(peer: ScriptedPeer) -> None:
    """While reconnecting, the latest N publishes per publisher are kept and sent after re-advertise."""
    async with roslibpy_lite.connect(peer.url, backoff=fast_backoff(), offline_buffer=2) as ros:
        pub = await ros.advertise("/buf", "std_msgs/msg/Int32")
        await peer.expect(op="advertise")
        url_port = peer.port
        await peer.drop()
        await peer.stop()
        await asyncio.wait_for(_until_state(ros, ConnectionState.RECONNECTING), 5)
        for i in range(5):
            await pub.publish({"data": i})
        assert pub.dropped == 3 and pub.offline_pending == 2
        mark = len(peer.received)
        peer.port = url_port
        await peer.start()
        await ros.wait_connected(10)
        await peer.expect(op="publish", start=mark, msg={"data": 4})
        sent = [(op["op"], op.get("msg")) for op in peer.received[mark:]]
        assert sent == [("advertise", None), ("publish", {"data": 3}), ("publish", {"data": 4})]


async def test_offline_buffer_zero_raises_disconnected(peer: ScriptedPeer) -> None:
    """With offline_buffer=0 a publish while the connection is down raises Disconnected."""
    async with roslibpy_lite.connect(peer.url, backoff=fast_backoff(), offline_buffer=0) as ros:
        pub = await ros.advertise("/nobuf", "std_msgs/msg/Int32")
        await peer.stop()
        await asyncio.wait_for(_until_state(ros, ConnectionState.RECONNECTING), 5)
        with pytest.raises(Disconnected, match="/nobuf"):
            await pub.publish({"data": 1})


async def test_call_made_while_reconnecting_waits_for_the_connection(peer: ScriptedPeer) -> None:
    """A call started while reconnecting with wait_connected=True is sent once connected
    again, within its timeout."""
    async with roslibpy_lite.connect(peer.url, backoff=fast_backoff()) as ros:
        port = peer.port
        await peer.stop()
        await asyncio.wait_for(_until_state(ros, ConnectionState.RECONNECTING), 5)
        peer.auto["call_service"] = lambda op: {
            "op": "service_response", "service": op["service"], "id": op["id"], "result": True,
            "values": {"result": 2.0},
        }
        call = asyncio.create_task(ros.call_service("/later", MULT, {}, timeout=20,
                                                    wait_connected=True))
        await asyncio.sleep(0)
        assert not call.done()
        peer.port = port
        await peer.start()
        assert await call == {"result": 2.0}


async def test_no_reconnect_means_closed_after_a_drop(peer: ScriptedPeer) -> None:
    """With reconnect=False a drop closes the client: iteration ends, calls raise ConnectionClosed."""
    async with roslibpy_lite.connect(peer.url, reconnect=False) as ros:
        sub = ros.subscribe("/end", "std_msgs/msg/Int32")
        await peer.expect(op="subscribe")
        await peer.drop()
        assert [m async for m in sub] == []
        assert ros.state is ConnectionState.CLOSED
        with pytest.raises(ConnectionClosed):
            await ros.call_service("/x", MULT, {})
        with pytest.raises(ConnectionClosed):
            ros.advertise("/x", "std_msgs/msg/Int32")


async def test_close_ends_iteration_and_fails_pending_calls(ros: Client, peer: ScriptedPeer) -> None:
    """close(): ``async for`` ends, a pending call raises ConnectionClosed, wait_connected raises."""
    sub = ros.subscribe("/x", "std_msgs/msg/Int32")
    call = asyncio.create_task(ros.call_service("/pending", MULT, {}, timeout=60))
    await peer.expect(op="call_service")
    seen: list[ConnectionState] = []
    ros.on_state_change(seen.append)
    await ros.close()
    assert [m async for m in sub] == []
    with pytest.raises(ConnectionClosed):
        await call
    with pytest.raises(ConnectionClosed):
        await ros.wait_connected(1)
    assert seen == [ConnectionState.CLOSED]


async def test_wait_connected_times_out_while_down(peer: ScriptedPeer) -> None:
    """wait_connected raises RosTimeoutError while the bridge stays away."""
    async with roslibpy_lite.connect(peer.url, backoff=fast_backoff()) as ros:
        await peer.stop()
        await asyncio.wait_for(_until_state(ros, ConnectionState.RECONNECTING), 5)
        with pytest.raises(RosTimeoutError, match="reconnecting"):
            await ros.wait_connected(0.1)


async def _until_state(ros: Client, state: ConnectionState) -> None:
    async with ros.state_changes() as changes:
        while ros.state is not state:
            await changes.next()


async def test_bad_url_is_a_usage_error() -> None:
    """A URL that is not ws:// or wss:// raises UsageError naming it."""
    with pytest.raises(UsageError, match="bad URL"):
        await roslibpy_lite.connect("http://127.0.0.1:1")


async def test_publish_backpressure_bounds_the_send_queue(peer: ScriptedPeer) -> None:
    """With max_pending=2, after every publish at most 2 frames wait; all arrive in order."""
    async with roslibpy_lite.connect(peer.url, max_pending=2) as ros:
        pub = await ros.advertise("/bp", "std_msgs/msg/Int32")
        for i in range(200):
            await pub.publish({"data": i})
            assert ros._ws.backlog <= 3
        await peer.expect(op="publish", msg={"data": 199})
        got = [op["msg"]["data"] for op in peer.received if op["op"] == "publish"]
        assert got == list(range(200))


async def test_status_error_reaches_every_publisher_of_the_topic(ros: Client) -> None:
    """A refused advertise fails the next publish of every handle sharing it."""
    a = await ros.advertise("/shared_bad", "nope_msgs/msg/Nope")
    b = await ros.advertise("/shared_bad", "nope_msgs/msg/Nope")
    ros._receive(json.dumps({"op": "status", "level": "error", "msg": "unknown type", "id": a.id}))
    for pub in (a, b):
        with pytest.raises(StatusError, match="unknown type"):
            await pub.publish({})


async def test_a_peer_that_drops_at_once_is_backed_off(peer: ScriptedPeer) -> None:
    """Connections that drop right after opening count as failures: the backoff grows."""
    async with roslibpy_lite.connect(peer.url, backoff=fast_backoff()) as ros:
        ros.stable_after = 3600.0  # every drop below counts as "at once", however slow the machine
        for n in range(2, 5):
            await peer.drop()
            await peer.wait_connections(n)
        assert ros.backoff.attempts >= 3
        await ros.wait_connected(10)
        ros.stable_after = 0.0
        await peer.drop()
        await peer.wait_connections(5)
        await ros.wait_connected(10)
        assert ros.backoff.attempts == 0


async def test_offline_publish_is_a_snapshot_and_checked_at_once(peer: ScriptedPeer) -> None:
    """A message buffered while down is copied at publish time; one JSON cannot carry fails then."""
    async with roslibpy_lite.connect(peer.url, backoff=fast_backoff(), validate=False) as ros:
        pub = await ros.advertise("/snap", "std_msgs/msg/String")
        port = peer.port
        await peer.stop()
        await asyncio.wait_for(_until_state(ros, ConnectionState.RECONNECTING), 5)
        msg = {"data": "first"}
        await pub.publish(msg)
        msg["data"] = "mutated later"
        with pytest.raises(roslibpy_lite.RosLibError, match="JSON"):
            await pub.publish({"data": {1, 2}})
        mark = len(peer.received)
        peer.port = port
        await peer.start()
        await peer.expect(op="publish", start=mark, topic="/snap")
        assert peer.count(start=mark, op="publish", msg={"data": "first"}) == 1
        assert pub.offline_pending == 0
