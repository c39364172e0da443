"""Foxglove through a relay (issues 26 and 28): the stock ``@foxglove/ws-protocol`` client
(npm, in Node: tests/peers/node/foxglove_peer.mjs) at ``ws://relay/robot1`` gets
``foxglove.websocket.v1`` on the relay's port, sees the robot's topics as channels with
their ``ros2msg`` schemas, and decodes the robot's CDR, carried over Zenoh untouched, to
what rclpy published; a rosbridge client on the same relay at the same time.

What the client sends goes the whole way too: its channels publish to an rclpy subscriber
on the robot in order, its service calls reach rclpy services, its parameter reads, sets and
updates reach the robot's nodes, and it follows the robot's connection graph and /clock;
every failure and refusal says what the robot's own bridge says to the same client
connected to it directly (one tier for those tests, the robot's bridge listening too).

The relay runs in this process, so the blocking peer driver is called off the event loop.
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import functools
import re
import threading
from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Any

import pytest
import pytest_asyncio
from std_msgs.msg import String

from bridge_server.foxglove.hub import foxglove_schema
from msgs import dynamic
from tests.helpers import open_wire
from tests.peers import scenarios
from tests.peers.peer import PeerError, PeerProcess, foxglove_peer
from tests.relay.support import ROBOT, Tier, tier, until

pytestmark = pytest.mark.timeout(120)

DEADLINE = scenarios.DEADLINE


async def _call(fn: Any, *args: Any, **kw: Any) -> Any:
    return await asyncio.to_thread(functools.partial(fn, *args, **kw))


async def _seen(fox: PeerProcess, pub: Any, topic: str, msg: Any) -> dict[str, Any]:
    """Publish from rclpy until the Foxglove client has a message on ``topic``."""
    deadline = asyncio.get_running_loop().time() + DEADLINE
    while True:
        pub.publish(msg)
        try:
            event: dict[str, Any] = await _call(
                fox.wait_event, lambda e: e.get("event") == "message" and e["topic"] == topic,
                0.5, f"message on {topic}")
            return event
        except AssertionError:
            assert asyncio.get_running_loop().time() < deadline, fox.diagnostics()


async def test_foxglove_client_through_a_relay(ros_node: Any, topic: str) -> None:
    """The Foxglove client through the relay: the protocol chosen, an rclpy Image's channel
    with its full schema, the Image decoded from the robot's CDR to what rclpy published; a
    rosbridge client of the same relay hears the robot too, and the robot's status page
    lists both, each with its protocol."""
    from sensor_msgs.msg import Image

    pub = ros_node.create_publisher(Image, topic, 10)
    chatter = ros_node.create_publisher(String, topic + "_chatter", 10)
    img = Image(height=48, width=64, encoding="rgb8", step=64 * 3, is_bigendian=0)
    img.header.frame_id = "camera"
    img.header.stamp.sec, img.header.stamp.nanosec = 12, 345
    img.data = bytes(i * 7 % 251 for i in range(64 * 48 * 3))
    async with tier() as t:
        fox = await _call(foxglove_peer, t.url())
        wire = await open_wire(t.url())
        try:
            assert fox.info["protocol"] == "foxglove.websocket.v1"
            channel = await _call(fox.request, "wait_channel", topic=topic,
                                  timeout_ms=int(DEADLINE * 1000), timeout=DEADLINE + 5)
            assert (channel["encoding"], channel["schemaEncoding"], channel["schemaName"]) == (
                "cdr", "ros2msg", "sensor_msgs/msg/Image")
            assert "uint32 height" in channel["schema"]
            assert "MSG: std_msgs/Header" in channel["schema"]
            await _call(fox.request, "subscribe", topic=topic, timeout_ms=int(DEADLINE * 1000),
                        timeout=DEADLINE + 5)
            msg = (await _seen(fox, pub, topic, img))["msg"]
            assert msg["header"] == {"stamp": {"sec": 12, "nanosec": 345},
                                     "frame_id": "camera"}
            assert (msg["height"], msg["width"], msg["encoding"], msg["step"]) == (
                48, 64, "rgb8", 192)
            assert base64.b64decode(msg["data"]["$bytes"]) == bytes(img.data)

            await wire.send({"op": "subscribe", "topic": topic + "_chatter",
                             "type": "std_msgs/msg/String"})
            deadline = asyncio.get_running_loop().time() + DEADLINE
            while True:
                chatter.publish(String(data="both"))
                try:
                    op = await wire.expect(op="publish", topic=topic + "_chatter", timeout=0.3)
                    break
                except AssertionError:
                    assert asyncio.get_running_loop().time() < deadline, "rosbridge heard nothing"
            assert op["msg"] == {"data": "both"}
            clients = t.relay.robots[ROBOT].web.local()["clients"]
            assert sorted(c["protocol"] for c in clients) == ["foxglove", "rosbridge"]
        finally:
            await wire.close()
            await _call(fox.close)


# -- publishing, services, parameters, the graph, the clock ------------------------------------
#
# One tier for these tests, whose robot bridge listens too: the same stock client on the
# robot's own port is what the relay is held to.


@dataclass
class Pair:
    """The tier, and one Foxglove client through the relay and one on the robot's bridge."""

    tier: Tier
    relay: PeerProcess
    direct: PeerProcess

    def begin_test(self) -> None:
        """Events of earlier tests are no longer looked at."""
        self.relay.begin_test()
        self.direct.begin_test()


@pytest_asyncio.fixture(scope="module", loop_scope="module")
async def pair() -> AsyncIterator[Pair]:
    """The module's tier (the robot's bridge listening) and its two Foxglove clients."""
    async with tier(websocket=True) as t:
        relay = await _call(foxglove_peer, t.url())
        try:
            direct = await _call(foxglove_peer, t.direct_url())
            try:
                yield Pair(t, relay, direct)
            finally:
                await _call(direct.close)
        finally:
            await _call(relay.close)


def _schema(type_name: str) -> str:
    """The definition text of a type as Foxglove clients give it."""
    return foxglove_schema(dynamic.full_text(type_name))


async def _error(fox: PeerProcess, part: str) -> str:
    """The text of the first status error (this test's) containing ``part``."""
    event = await _call(fox.wait_event, lambda e: e.get("event") == "status"
                        and e.get("level") == 2 and part in e.get("message", ""), DEADLINE,
                        f"a status error with {part!r}")
    return str(event["message"])


async def _failure(fox: PeerProcess, cmd: str, **params: Any) -> str:
    """What a call command's ``serviceCallFailure`` said (it must fail)."""
    try:
        answer = await _call(fox.request, cmd, timeout=DEADLINE + 5, **params)
    except PeerError as exc:
        text = str(exc)
        assert "serviceCallFailure: " in text, text
        return text.split("serviceCallFailure: ", 1)[1]
    raise AssertionError(f"the call was answered: {answer}")


async def _publish_until_heard(fox: PeerProcess, topic: str, text: str, got: list[str]
                               ) -> None:
    """Publish ``text`` on the client's channel of ``topic`` until the robot's subscriber
    got something (its publisher matching the subscriber has no event here)."""
    deadline = asyncio.get_running_loop().time() + DEADLINE
    while not got:
        assert asyncio.get_running_loop().time() < deadline, fox.diagnostics()
        await _call(fox.request, "publish", topic=topic, msg={"data": text})
        with contextlib.suppress(AssertionError):
            await until(lambda: got, f"a message on {topic}", scenarios.ATTEMPT)


@pytest.mark.asyncio(loop_scope="module")
async def test_a_foxglove_client_publishes_to_the_robot_through_a_relay(
        pair: Pair, ros_node: Any, topic: str) -> None:
    """clientAdvertise and CDR message data through the relay reach an rclpy subscriber on
    the robot, every message in the order sent; clientUnadvertise takes the robot's ROS
    publisher away; a json channel's message reaches rclpy too."""
    pair.begin_test()
    fox = pair.relay
    got: list[str] = []
    ros_node.create_subscription(String, topic, lambda m: got.append(m.data), 100)
    await _call(fox.request, "advertise", topic=topic, schemaName="std_msgs/msg/String",
                schema=_schema("std_msgs/msg/String"))
    await _publish_until_heard(fox, topic, "hello", got)
    sent = [f"n{i}" for i in range(40)]
    for text in sent:
        await _call(fox.request, "publish", topic=topic, msg={"data": text})
    await until(lambda: sent[-1] in got, "the last message on the robot", DEADLINE)
    assert [m for m in got if m != "hello"] == sent
    await _call(fox.request, "unadvertise", topic=topic)
    await until(lambda: ros_node.count_publishers(topic) == 0, "the robot's publisher to go",
                DEADLINE)

    as_json: list[str] = []
    ros_node.create_subscription(String, topic + "_json", lambda m: as_json.append(m.data), 10)
    await _call(fox.request, "advertise", topic=topic + "_json",
                schemaName="std_msgs/msg/String", encoding="json")
    await _publish_until_heard(fox, topic + "_json", "as json", as_json)
    assert as_json[0] == "as json"


@pytest.mark.asyncio(loop_scope="module")
async def test_a_foxglove_client_calls_the_robots_services_through_a_relay(
        pair: Pair, ros_node: Any, topic: str) -> None:
    """serviceCallRequest through the relay calls an rclpy service on the robot and gets its
    answer (CDR); an unknown service, a request that does not decode, arguments the type
    does not take and a server that does not answer in time each get a serviceCallFailure
    with the words the robot's own bridge uses."""
    from std_srvs.srv import SetBool

    pair.begin_test()
    release = threading.Event()

    def answer(request: Any, response: Any) -> Any:
        response.success = request.data
        response.message = f"rclpy got {request.data}"
        return response

    def stuck(request: Any, response: Any) -> Any:
        release.wait(DEADLINE)
        return response

    ros_node.create_service(SetBool, topic, answer)
    ros_node.create_service(SetBool, topic + "_stuck", stuck)
    try:
        reply = await _call(pair.relay.request, "call_service", service=topic,
                            request={"data": True}, timeout_ms=int(DEADLINE * 1000),
                            timeout=DEADLINE + 5)
        assert reply == {"encoding": "cdr", "value": {"success": True,
                                                      "message": "rclpy got True"}}
        ids = {}
        for name, fox in (("relay", pair.relay), ("direct", pair.direct)):
            service = await _call(fox.request, "service", service=topic + "_stuck",
                                  timeout_ms=int(DEADLINE * 1000), timeout=DEADLINE + 5)
            ids[name] = (service["id"], (await _call(fox.request, "service", service=topic))["id"])
        said: dict[str, list[str]] = {}
        for name, fox in (("relay", pair.relay), ("direct", pair.direct)):
            good = ids[name][1]
            said[name] = [
                await _failure(fox, "call_service_id", service_id=987654, hex="00010000"),
                await _failure(fox, "call_service_id", service_id=good, hex="0001"),
                await _failure(fox, "call_service_id", service_id=good, encoding="json",
                               hex=b'{"data": "yes"}'.hex()),
                await _failure(fox, "call_service_id", service_id=good, encoding="json",
                               hex=b'{"nope": true}'.hex()),
            ]
        stuck_calls = [
            _failure(fox, "call_service_id", service_id=ids[name][0], hex="0001000001")
            for name, fox in (("relay", pair.relay), ("direct", pair.direct))]
        timed_out = await asyncio.gather(*stuck_calls)
    finally:
        release.set()
    assert said["relay"] == said["direct"]
    assert "no service 987654" in said["relay"][0]
    assert "does not decode as std_srvs/srv/SetBool" in said["relay"][1]
    assert timed_out[0] == timed_out[1]


async def _parameters(fox: PeerProcess, request_id: str, cmd: str, **params: Any
                      ) -> list[dict[str, Any]]:
    """Send a parameter command with ``request_id``; the ``parameterValues`` answering it."""
    await _call(fox.request, cmd, id=request_id, **params)
    event = await _call(fox.wait_event, lambda e: e.get("event") == "parameterValues"
                        and e["id"] == request_id, DEADLINE, f"parameterValues {request_id}")
    found: list[dict[str, Any]] = event["parameters"]
    return found


async def _update(fox: PeerProcess, entry: dict[str, Any]) -> None:
    """Wait for a parameter update event (no id) that holds ``entry``."""
    await _call(fox.wait_event, lambda e: e.get("event") == "parameterValues"
                and e["id"] is None and entry in e["parameters"], DEADLINE,
                f"an update with {entry}")


@pytest.mark.asyncio(loop_scope="module")
async def test_a_foxglove_client_reads_sets_and_follows_parameters_through_a_relay(
        pair: Pair, ros_node: Any) -> None:
    """getParameters (one by one and all at once), setParameters (a float and a byte array)
    and parameter updates through the relay reach an rclpy node's parameters of every type on
    the robot, each as the spec has it (a byte array as base64 text typed byte_array, whoever
    set it); a name that is not /node.param and a value no parameter holds get the errors
    the robot's own bridge gives."""
    from rclpy.parameter import Parameter

    pair.begin_test()
    fox = pair.relay
    declared = scenarios.declare_foxglove_parameters(ros_node, "")
    names = [name for name, _ in declared]
    entries = [entry for _, entry in declared]
    node = ros_node.get_fully_qualified_name()
    gain, blob = f"{node}.gain", f"{node}.blob"
    await _call(fox.request, "subscribe_parameters", names=[gain, blob])
    deadline = asyncio.get_running_loop().time() + DEADLINE
    n = 0
    while not (values := await _parameters(fox, f"get{n}", "get_parameters", names=names)):
        assert asyncio.get_running_loop().time() < deadline, "the robot never saw the node"
        n += 1  # until the robot's bridge sees the new node (no event)
    assert values == entries
    assert await _parameters(pair.direct, "direct", "get_parameters", names=names) == entries
    n = 0  # the robot's graph lists the node's parameter services a moment later (no event)
    while (every := [p for p in await _parameters(fox, f"all{n}", "get_parameters", names=[])
                     if p["name"] in names]) != entries:
        assert asyncio.get_running_loop().time() < deadline, every
        n += 1
    assert every == entries
    assert await _parameters(fox, "set1", "set_parameters", parameters=[
        {"name": gain, "value": 3, "type": "float64"}]) == [
        {"name": gain, "value": 3.0, "type": "float64"}]
    assert ros_node.get_parameter("gain").value == 3.0
    await _update(fox, {"name": gain, "value": 3.0, "type": "float64"})
    hi = {"name": blob, "value": "aGk=", "type": "byte_array"}
    assert await _parameters(fox, "set2", "set_parameters", parameters=[hi]) == [hi]
    assert ros_node.get_parameter("blob").value == [b"h", b"i"]
    await _update(fox, hi)
    by_ros = Parameter("blob", Parameter.Type.BYTE_ARRAY,  # type: ignore[no-untyped-call]
                       [b"r", b"o", b"s"])
    ros_node.set_parameters([by_ros])
    ros = {"name": blob, "value": "cm9z", "type": "byte_array"}
    await _update(fox, ros)
    assert await _parameters(fox, "get_blob", "get_parameters", names=[blob]) == [ros]

    said: dict[str, list[str]] = {}
    for name, peer in (("relay", pair.relay), ("direct", pair.direct)):
        await _call(peer.request, "get_parameters", names=["no_dot"], id="bad")
        await _call(peer.request, "set_parameters", id="bad", parameters=[
            {"name": gain, "value": {"a": 1}}])
        said[name] = [await _error(peer, "'no_dot'"), await _error(peer, f"{gain}:")]
    assert said["relay"] == said["direct"]
    assert ros_node.get_parameter("gain").value == 3.0


@pytest.mark.asyncio(loop_scope="module")
async def test_a_foxglove_clients_bad_publishing_gets_the_robots_bridges_errors(
        pair: Pair, ros_node: Any, topic: str) -> None:
    """What a client cannot publish through the relay (an encoding, a name or a type that
    does not fit, CDR that does not decode, no such channel) gets the status error the
    robot's own bridge gives it."""
    pair.begin_test()
    ros_node.create_publisher(String, topic + "_typed", 10)
    await until(lambda: all(topic + "_typed" in dict(b.graph.topic_names_and_types())
                            for b in (pair.tier.robot, *pair.tier.relay.robots.values())),
                "the robot's topic in the relay's graph", DEADLINE)
    string = _schema("std_msgs/msg/String")
    said: dict[str, list[str]] = {}
    for name, fox in (("relay", pair.relay), ("direct", pair.direct)):
        for args, part in [
                ({"topic": topic + "_p", "schemaName": "std_msgs/msg/String",
                  "encoding": "protobuf"}, "encoding 'protobuf'"),
                ({"topic": topic + " bad", "schemaName": "std_msgs/msg/String",
                  "schema": string}, "bad):"),
                ({"topic": topic + "_typed", "schemaName": "std_msgs/msg/Int32",
                  "schema": _schema("std_msgs/msg/Int32")}, "not std_msgs/msg/Int32"),
                ({"topic": topic, "schemaName": "std_msgs/msg/String", "schema": string},
                 None)]:
            await _call(fox.request, "advertise", **args)
            if part is not None:
                await _error(fox, part)
        await _call(fox.request, "publish_bytes", topic=topic, hex="00010000ff000000")
        await _error(fox, f"message data on {topic}")
        await _call(fox.request, "send_binary", hex="01" + "39300000" + "00010000")
        await _error(fox, "no client channel 12345")
        said[name] = [re.sub(r"channel \d+ \(", "channel N (", e["message"])
                      for e in fox.new_events()
                      if e.get("event") == "status" and e.get("level") == 2]
        await _call(fox.request, "unadvertise", topic=topic)
    assert said["relay"] == said["direct"]
    assert len(said["relay"]) == 5, said


@pytest.mark.asyncio(loop_scope="module")
async def test_a_foxglove_client_follows_the_robots_connection_graph_through_a_relay(
        pair: Pair, ros_node: Any, topic: str) -> None:
    """subscribeConnectionGraph through the relay: the update names the rclpy node on the
    robot that publishes a topic, subscribes to one and serves a service."""
    from std_srvs.srv import SetBool

    pair.begin_test()
    fox = pair.relay
    ros_node.create_publisher(String, topic + "_out", 10)
    ros_node.create_subscription(String, topic + "_in", lambda m: None, 10)
    ros_node.create_service(SetBool, topic + "_srv", lambda req, res: res)
    me = f"/{ros_node.get_name()}"
    await _call(fox.request, "wait_channel", topic=topic + "_out",
                timeout_ms=int(DEADLINE * 1000), timeout=DEADLINE + 5)
    await _call(fox.request, "subscribe_graph")
    seen: dict[str, bool] = {}

    def names_me(event: dict[str, Any]) -> bool:
        if event.get("event") != "connectionGraphUpdate":
            return False
        update = event["update"]
        for key, ids, name in (("publishedTopics", "publisherIds", topic + "_out"),
                               ("subscribedTopics", "subscriberIds", topic + "_in"),
                               ("advertisedServices", "providerIds", topic + "_srv")):
            if any(t["name"] == name and me in t[ids] for t in update.get(key, [])):
                seen[key] = True
        return len(seen) == 3

    await _call(fox.wait_event, names_me, DEADLINE, "graph updates naming the robot's node")


@pytest.mark.asyncio(loop_scope="module")
async def test_a_foxglove_client_follows_the_robots_clock_through_a_relay(
        pair: Pair, ros_node: Any) -> None:
    """With /clock published on the robot, a Foxglove client that connects to the relay is
    offered 'time' and sent the robot's clock."""
    from rosgraph_msgs.msg import Clock  # type: ignore[import-untyped]

    clock = ros_node.create_publisher(Clock, "/clock", 10)
    try:
        relayed = await pair.tier.relay.robot(ROBOT)
        assert relayed is not None
        await until(lambda: "/clock" in dict(relayed.graph.topic_names_and_types()),
                    "/clock in the relay's graph of the robot", DEADLINE)
        fox = await _call(foxglove_peer, pair.tier.url())
        try:
            assert "time" in fox.info["serverInfo"]["capabilities"]
            msg = Clock()
            msg.clock.sec, msg.clock.nanosec = 1234, 5678
            deadline = asyncio.get_running_loop().time() + DEADLINE
            while True:  # until the robot's /clock subscription matched (no event)
                clock.publish(msg)
                with contextlib.suppress(AssertionError):
                    event = await _call(fox.wait_event, lambda e: e.get("event") == "time",
                                        scenarios.ATTEMPT, "time")
                    break
                assert asyncio.get_running_loop().time() < deadline, fox.diagnostics()
            assert event["timestamp"] == {"$bigint": str(1234 * 10**9 + 5678)}
        finally:
            await _call(fox.close)
    finally:
        ros_node.destroy_publisher(clock)


async def test_a_foxglove_client_is_told_its_robot_went_away_and_is_back() -> None:
    """The robot's link to the relay's network goes (its exporter closed) and comes back (a
    new one): the stock Foxglove client through the relay gets a warning status naming the
    robot and that it went away, then an info status that it is back."""
    from bridge_server.zenoh.exporter import Exporter
    from bridge_server.zenoh.link import ZenohOptions

    async with tier() as t:
        fox = await _call(foxglove_peer, t.url())
        try:
            await t.exporter.close()
            gone = await _call(fox.wait_event, lambda e: e.get("event") == "status"
                               and e.get("level") == 1, DEADLINE, "a warning status")
            assert f"robot {ROBOT} went away" in gone["message"], gone
            t.exporter = Exporter(t.robot.graph, ROBOT, ZenohOptions(connect=[t.router]),
                                  graph_changed=t.robot.graph_changed, snapshot_interval=0.2)
            t.exporter.start()
            back = await _call(fox.wait_event, lambda e: e.get("event") == "status"
                               and e.get("level") == 0, DEADLINE, "an info status")
            assert f"robot {ROBOT} is back" in back["message"], back
        finally:
            await _call(fox.close)
