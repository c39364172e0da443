"""The relay tier in one process (tests/relay/support.py): a robot's rclpy topics, services and
own types reach websocket clients of a relay without ROS, and back; the robot subscribes in
ROS only while someone watches."""

from __future__ import annotations

import asyncio
import struct
import sys
from pathlib import Path
from typing import Any

import pytest
from std_msgs.msg import String
from std_srvs.srv import SetBool

import roslibpy_lite
from tests.helpers import open_wire, ros_env
from tests.relay.support import ROBOT, robot_reachable, start_relay, tier, until
from tests.security.support import make_certs

pytestmark = pytest.mark.timeout(90)


async def _first(ws: Any, publish: Any, topic: str, timeout: float = 20.0) -> Any:
    """Publish from rclpy until the client hears the topic (discovery has no event)."""
    deadline = asyncio.get_running_loop().time() + timeout
    while True:
        publish()
        try:
            return await ws.expect(op="publish", topic=topic, timeout=0.3)
        except AssertionError:
            if asyncio.get_running_loop().time() > deadline:
                raise


@pytest.mark.parametrize("compression", ["none", "cbor", "cbor-raw", "none over tls"])
async def test_a_robot_topic_reaches_a_relay_client(ros_node: Any, topic: str,
                                                    compression: str, tmp_path: Path) -> None:
    """An rclpy String on the robot reaches a client of the relay as JSON, CBOR and cbor-raw
    (the CDR bytes the robot's ROS subscription took), and over a tls/ Zenoh link (the robot
    trusting the router's CA)."""
    pub = ros_node.create_publisher(String, topic, 10)
    tls = None
    if compression.endswith(" over tls"):
        compression = compression.split()[0]
        certs = make_certs(tmp_path)
        tls = (str(certs.ca), str(certs.server))
    async with tier(tls) as t:
        ws = await open_wire(t.url())
        try:
            await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String",
                           "compression": compression})
            op = await _first(ws, lambda: pub.publish(String(data="through the relay")), topic)
            if compression == "cbor-raw":
                raw = op["msg"]["bytes"]
                (length,) = struct.unpack_from("<I", raw, 4)
                assert raw[8:8 + length - 1] == b"through the relay"
                assert op["msg"]["secs"] > 1_700_000_000
            else:
                assert op["msg"] == {"data": "through the relay"}
        finally:
            await ws.close()


async def test_a_client_publishes_to_the_robot(ros_node: Any, topic: str) -> None:
    """A relay client's advertise and publish reach an rclpy subscriber on the robot (the
    robot publishes the CDR bytes the relay made from the client's JSON)."""
    got: list[str] = []
    ros_node.create_subscription(String, topic, lambda m: got.append(m.data), 10)
    async with tier() as t:
        ws = await open_wire(t.url())
        try:
            await ws.send({"op": "advertise", "topic": topic, "type": "std_msgs/msg/String"})
            n = 0
            deadline = asyncio.get_running_loop().time() + 20
            while not got:  # until the robot's publisher matched the rclpy subscriber
                n += 1
                await ws.send({"op": "publish", "topic": topic, "msg": {"data": f"hi {n}"}})
                await asyncio.sleep(0.1)
                assert asyncio.get_running_loop().time() < deadline, "nothing reached ROS"
            assert got[0].startswith("hi ")
            await ws.send({"op": "publish", "topic": topic, "msg": {"data": 5}})
            error = await ws.expect(op="status", level="error")
            assert "data" in error["msg"] and "string" in error["msg"], error
        finally:
            await ws.close()


async def test_a_message_no_relay_advertises_leaves_no_publisher(ros_node: Any, topic: str
                                                                 ) -> None:
    """A message under ``@in/`` that no relay's ``@advertise`` token holds (one that came after
    its relay unadvertised, or from a relay that declares none; a plain Zenoh session plays
    it) gets a publisher on the robot that leaves ROS after a while instead of staying for
    good; one whose token comes after its first message stays while the token lives."""
    from bridge_server.zenoh import keys
    from bridge_server.zenoh.keys import Meta
    from bridge_server.zenoh.link import ZenohOptions, open_session
    from msgs import cdr
    from msgs.std_msgs.msg import String as WireString

    async with tier() as t:
        t.exporter.unheld_wait = 0.5
        session = await open_session(ZenohOptions(connect=[t.router]))
        try:
            entry = (topic, "std_msgs/msg/String", False)

            def put(text: str) -> bool:
                """Put a message (again until the exporter has its publisher: a session
                just opened may not know the robot's subscriber yet)."""
                if entry not in t.exporter.publishers:
                    session.put(keys.key_of(ROBOT, topic, keys.IN),
                                cdr.encode(WireString(data=text)),
                                attachment=Meta(type="std_msgs/msg/String").encode())
                return entry in t.exporter.publishers

            await until(lambda: put("stray"), "the robot's publisher of the stray message")
            await until(lambda: not t.exporter.publishers, "the unheld publisher to go")
            await until(lambda: ros_node.count_publishers(topic) == 0,
                        "the unheld publisher to leave ROS")

            # the token comes after the first message: the publisher stays while it is held
            t.exporter.unheld_wait = 2.0
            await until(lambda: put("first"), "the robot's publisher of the first message")
            token = session.liveliness().declare_token(
                keys.advertise_key(ROBOT, "played", topic, "std_msgs/msg/String", False))
            await until(lambda: "played" in t.exporter.publishers.get(entry, (None, set()))[1],
                        "the relay's token to hold the publisher")
            await until(lambda: ros_node.count_publishers(topic) == 1, "the publisher in ROS")
            await until(lambda: entry not in t.exporter._unheld, "the unheld wait to end")
            assert entry in t.exporter.publishers, "a held publisher went"
            token.undeclare()  # type: ignore[no-untyped-call]
            await until(lambda: ros_node.count_publishers(topic) == 0,
                        "the publisher to go with its token")
        finally:
            await asyncio.to_thread(session.close)


async def test_latched_both_ways(ros_node: Any, topic: str) -> None:
    """A latched rclpy topic's one message reaches relay clients that subscribe after it was
    sent (the first through the robot, the second from the relay's copy); a client's latched
    publisher gives a transient-local rclpy subscriber the last message."""
    from rclpy.qos import DurabilityPolicy, QoSProfile

    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)  # type: ignore[no-untyped-call]
    pub = ros_node.create_publisher(String, topic, latched)
    pub.publish(String(data="the map"))
    async with tier() as t:
        first, second = await open_wire(t.url()), await open_wire(t.url())
        try:
            await first.send({"op": "subscribe", "topic": topic})
            op = await first.expect(op="publish", topic=topic, timeout=20)
            assert op["msg"] == {"data": "the map"}
            await second.send({"op": "subscribe", "topic": topic})
            op = await second.expect(op="publish", topic=topic, timeout=10)
            assert op["msg"] == {"data": "the map"}
            with pytest.raises(AssertionError):  # once each, not again
                await first.expect(op="publish", topic=topic, timeout=0.5)

            back = topic + "_back"
            await first.send({"op": "advertise", "topic": back, "type": "std_msgs/msg/String",
                              "latch": True})
            await first.send({"op": "publish", "topic": back, "msg": {"data": "kept"}})
            await until(lambda: back in [n for n, _ in t.robot.graph.topic_names_and_types()],
                        "the robot's latched publisher")
            got: list[str] = []
            ros_node.create_subscription(String, back, lambda m: got.append(m.data), latched)
            await until(lambda: got, "the latched message in ROS")
            assert got == ["kept"]
        finally:
            await first.close()
            await second.close()


async def test_a_service_call_through_the_relay(ros_node: Any, topic: str) -> None:
    """call_service through the relay is answered by an rclpy service on the robot; a call to a
    service the robot does not have fails with the robot's reason."""
    def answer(req: Any, res: Any) -> Any:
        res.message = f"got {req.data}"
        return res

    ros_node.create_service(SetBool, topic, answer)
    async with tier() as t:
        ws = await open_wire(t.url())
        try:
            await ws.send({"op": "call_service", "service": topic, "type": "std_srvs/srv/SetBool",
                           "args": {"data": True}, "id": "c1"})
            reply = await ws.expect(op="service_response", id="c1", timeout=20)
            assert reply["result"] is True, reply
            assert reply["values"] == {"success": False, "message": "got True"}
            await ws.send({"op": "call_service", "service": topic + "_none", "id": "c2",
                           "timeout": 1})
            reply = await ws.expect(op="service_response", id="c2", timeout=20)
            assert reply["result"] is False
            assert "does not exist" in reply["values"], reply
        finally:
            await ws.close()


def _typed(value: Any) -> list[Any]:
    """The values of an RFC 8746 typed array (a CBOR tag: anything else fails)."""
    import cbor2

    from rosbridge_core.protocol.frames import decode_typed_array

    assert isinstance(value, cbor2.CBORTag), value
    return decode_typed_array(value.tag, value.value)


async def test_the_robots_own_type(ros_node: Any, topic: str) -> None:
    """A type installed only on the robot (robot_msgs, which msgs does not generate) is
    decoded by the relay from the definition the robot sent, and its typedefs and definition
    are the robot's."""
    from robot_msgs.msg import Status, Wheel

    pub = ros_node.create_publisher(Status, topic, 10)
    msg = Status(mode=1, label="rover", blob=b"\x01\x02", battery_cells=[3.5, 3.75],
                 wheels=[Wheel(name="left", speed=0.5, ticks=[1, 2, 3])])
    async with tier() as t:
        ws = await open_wire(t.url())
        try:
            await ws.send({"op": "subscribe", "topic": topic, "compression": "cbor"})
            op = await _first(ws, lambda: pub.publish(msg), topic)
            got = op["msg"]
            assert got["label"] == "rover" and got["mode"] == 1 and got["blob"] == b"\x01\x02"
            # numeric arrays as typed arrays, as the bridge sends them (test_relay_cbor.py)
            assert got["wheels"][0]["name"] == "left" and _typed(got["wheels"][0]["ticks"]) == [
                1, 2, 3]
            assert _typed(got["battery_cells"]) == [3.5, 3.75]
            await ws.send({"op": "call_service", "service": "/rosapi/message_details",
                           "args": {"type": "robot_msgs/msg/Status"}, "id": "d"})
            reply = await ws.expect(op="service_response", id="d")
            names = [d["type"] for d in reply["values"]["typedefs"]]
            assert names[0] == "robot_msgs/msg/Status" and "robot_msgs/msg/Wheel" in names
        finally:
            await ws.close()


async def test_demand_drives_the_robots_subscriptions(ros_node: Any, topic: str) -> None:
    """The robot has no ROS subscription to a topic while no relay client watches it; it
    subscribes with the first viewer, keeps it while one is left, and drops it when the last
    leaves and when the relay itself goes."""
    pub = ros_node.create_publisher(String, topic, 10)
    async with tier() as t:
        subs = t.robot.graph.subscriptions
        assert topic not in subs
        a, b = await open_wire(t.url()), await open_wire(t.url())
        await a.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String"})
        await _first(a, lambda: pub.publish(String(data="x")), topic)
        assert topic in subs and t.demand(topic) == {t.relay.relay_id}
        await b.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String"})
        await _first(b, lambda: pub.publish(String(data="y")), topic)
        await a.close()
        served = t.relay.robots[ROBOT]
        await until(lambda: len(served.sessions) == 1, "the relay to see the first viewer go")
        b.backlog.clear()
        await _first(b, lambda: pub.publish(String(data="still")), topic)  # b's feed goes on
        assert topic in subs
        await b.close()
        await until(lambda: topic not in subs, "the robot to unsubscribe after the last viewer")
        again = await open_wire(t.url())
        await again.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String"})
        await until(lambda: topic in subs, "the robot to subscribe again")
        await t.relay.close()  # the relay dies: its demand token vanishes with its session
        await until(lambda: topic not in subs, "the robot to unsubscribe after the relay went")


async def test_a_path_naming_no_robot_is_refused() -> None:
    """A client asking for a robot that is not on Zenoh (or naming none, or a name that is
    not one) is refused before the handshake with the reason; the robot's own path works."""
    from websockets.asyncio.client import connect
    from websockets.exceptions import InvalidStatus

    async with tier() as t:
        base = f"ws://127.0.0.1:{t.relay.port}"
        for path, status, words in (("/robot2", 404, "no robot named 'robot2'"),
                                    ("/", 404, "name a robot in the path"),
                                    ("/@alive", 400, "invalid robot name '@alive'")):
            with pytest.raises(InvalidStatus) as refused:
                async with connect(base + path, open_timeout=10):
                    pass
            response = refused.value.response
            assert response.status_code == status, path
            assert words in response.body.decode(), response.body
        async with connect(t.url(), open_timeout=10):
            pass


async def _served_call(ros_node: Any, ws: Any, topic: str, data: bool) -> Any:
    """An rclpy client on the robot calls ``topic``; the relay client ``ws`` answers it."""
    client = ros_node.create_client(SetBool, topic)
    try:
        await until(client.service_is_ready, "the robot to serve the relay client's service")
        future = client.call_async(SetBool.Request(data=data))
        call = await ws.expect(op="call_service", service=topic, timeout=20)
        assert call["args"] == {"data": data}, call
        await ws.send({"op": "service_response", "service": topic, "id": call["id"],
                       "result": True, "values": {"success": data, "message": "from the relay"}})
        await until(future.done, "the ROS caller's answer")
        return future.result()
    finally:
        ros_node.destroy_client(client)


async def test_a_relay_client_serves_a_service_rclpy_calls(ros_node: Any, topic: str) -> None:
    """A relay client's advertise_service is served in ROS on the robot: an rclpy client's
    call reaches the relay client and its answer comes back; a client of another relay is
    told who serves it; the service leaves ROS when the client goes and when the relay
    dies."""
    probe = ros_node.create_client(SetBool, topic)
    async with tier() as t:
        ws = await open_wire(t.url())
        await ws.send({"op": "advertise_service", "service": topic,
                       "type": "std_srvs/srv/SetBool"})
        response = await _served_call(ros_node, ws, topic, True)
        assert (response.success, response.message) == (True, "from the relay")
        assert t.exporter.snapshot.served == {topic: t.relay.relay_id}
        await ws.close()
        await until(lambda: not probe.service_is_ready(), "the service to leave ROS with its "
                    "client")

        ws = await open_wire(t.url())
        await ws.send({"op": "advertise_service", "service": topic,
                       "type": "std_srvs/srv/SetBool"})
        response = await _served_call(ros_node, ws, topic, False)
        assert (response.success, response.message) == (False, "from the relay")
        second = await start_relay(router=t.router)
        try:
            await robot_reachable(second)
            other = await open_wire(f"ws://127.0.0.1:{second.port}/{ROBOT}")
            graph = second.robots[ROBOT].graph
            await until(lambda: graph.other_servers(topic), "the second relay to see it served")
            await other.send({"op": "advertise_service", "service": topic,
                              "type": "std_srvs/srv/SetBool"})
            error = await other.expect(op="status", level="error")
            assert f"already served by a client of relay {t.relay.relay_id}" in error["msg"]
            await other.close()
        finally:
            await second.close()
        await t.relay.close()
        await until(lambda: not probe.service_is_ready(), "the service to leave ROS with the "
                    "relay")
        assert not t.exporter.served
        await ws.close()
    ros_node.destroy_client(probe)


async def test_a_robot_nodes_parameters_through_the_relay(ros_node: Any) -> None:
    """/rosapi/get_param_names, get_param and set_param through the relay read and write an
    rclpy node's parameter on the robot (a byte array read as its numbers, as on the bridge); a
    value no parameter can hold and a node that is not there are named as on the bridge."""
    ros_node.declare_parameter("gain", 1.5)
    ros_node.declare_parameter("blob", [b"h", b"i"])
    node = ros_node.get_fully_qualified_name()
    async with tier() as t:
        ws = await open_wire(t.url())

        async def call(service: str, args: dict[str, Any]) -> Any:
            await ws.send({"op": "call_service", "service": f"/rosapi/{service}", "id": service,
                           "args": args})
            return await ws.expect(op="service_response", id=service, timeout=20)

        try:
            await until(lambda: node in [ns.rstrip("/") + "/" + n for n, ns in
                                         t.relay.robots[ROBOT].graph.node_names()],
                        "the relay to list the node")
            # the node's name can reach the robot's graph before its parameter services do:
            # until they have, the robot lists none of its parameters
            for _ in range(200):
                reply = await call("get_param_names", {})
                if f"{node}:gain" in reply["values"]["names"]:
                    break
                await asyncio.sleep(0.1)
            assert f"{node}:gain" in reply["values"]["names"], reply
            reply = await call("get_param", {"name": f"{node}:gain"})
            assert reply["values"]["value"] == "1.5", reply
            reply = await call("get_param", {"name": f"{node}:blob"})
            assert reply["values"]["value"] == "[104, 105]", reply
            reply = await call("set_param", {"name": f"{node}:gain", "value": "2.5"})
            assert reply["result"] is True, reply
            assert ros_node.get_parameter("gain").value == 2.5
            reply = await call("set_param", {"name": f"{node}:gain", "value": '[1, "a"]'})
            assert reply["result"] is False, reply
            assert "a ROS 2 parameter is a bool, int, float, string or a list" in \
                reply["values"], reply
            reply = await call("get_param", {"name": "/no_such_node:gain"})
            assert reply["result"] is False, reply
            assert "node /no_such_node does not answer parameter requests" in reply["values"]
        finally:
            await ws.close()


async def test_a_second_relay_on_the_first_ones_router(ros_node: Any, topic: str) -> None:
    """A relay that is a Zenoh client of the first relay's router serves the same robot; the
    robot knows both relays watch the topic and still holds one ROS subscription."""
    pub = ros_node.create_publisher(String, topic, 10)
    async with tier() as t:
        second = await start_relay(router=t.router)
        try:
            await robot_reachable(second)
            one = await open_wire(t.url())
            two = await open_wire(f"ws://127.0.0.1:{second.port}/{ROBOT}")
            for ws in (one, two):
                await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String"})
            await _first(one, lambda: pub.publish(String(data="both")), topic)
            await _first(two, lambda: pub.publish(String(data="both")), topic)
            assert t.demand(topic) == {t.relay.relay_id, second.relay_id}
            assert list(t.robot.graph.subscriptions).count(topic) == 1
            await one.close()
            await two.close()
        finally:
            await second.close()


async def test_our_client_and_stock_roslibpy_through_the_relay(ros_node: Any, topic: str) -> None:
    """roslibpy_lite and roslibpy from PyPI (unchanged, in a child process) subscribe through
    the relay by URL and get the robot's messages."""
    pub = ros_node.create_publisher(String, topic, 10)
    stop = asyncio.Event()

    async def keep_publishing() -> None:  # discovery has no event: publish until all heard
        n = 0
        while not stop.is_set():
            n += 1
            pub.publish(String(data=f"m{n}"))
            await asyncio.sleep(0.05)

    async with tier() as t:
        publisher = asyncio.create_task(keep_publishing())
        script = (
            "import sys, threading, roslibpy\n"
            "ros = roslibpy.Ros(sys.argv[1])\n"
            "ros.run(timeout=20)\n"
            "got = threading.Event()\n"
            "t = roslibpy.Topic(ros, sys.argv[2], 'std_msgs/String')\n"
            "t.subscribe(lambda m: (print('GOT', m['data'], flush=True), got.set()))\n"
            "print('OK' if got.wait(20) else 'NOTHING', flush=True)\n"
            "ros.terminate()\n"
        )
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-c", script, t.url(), topic, stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.STDOUT, env=ros_env())
        try:
            async with roslibpy_lite.connect(t.url()) as ros:
                sub = ros.subscribe(topic, "std_msgs/msg/String")
                msg = await sub.get(20)
                assert msg["data"].startswith("m")
            out, _ = await asyncio.wait_for(proc.communicate(), 60)
            text = out.decode()
            assert "GOT m" in text and "OK" in text, text
        finally:
            stop.set()
            await publisher
            if proc.returncode is None:
                proc.kill()
                await proc.wait()


@pytest.mark.parametrize(("argv", "words"), [
    (["--zenoh-connect", "tcp/127.0.0.1:7447"], "--zenoh-connect needs --robot NAME"),
    (["--zenoh-connect", "tcp/127.0.0.1:7447", "--robot", "my robot"],
     "--robot: invalid robot name 'my robot'"),
    (["--zenoh-connect", "tcp/127.0.0.1:7447", "--robot", "@alive"],
     "--robot: invalid robot name '@alive'"),
])
def test_the_robots_command_line_refuses_a_bad_robot(argv: list[str], words: str,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """The robot's bridge does not start without a usable robot name, and says which option
    is wrong and why."""
    from bridge_server.__main__ import main

    assert main(["--no-websocket", *argv]) == 2
    assert words in capsys.readouterr().err


def test_the_relays_command_line_refuses_bad_zenoh_options(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """A relay with no Zenoh endpoint, a missing TLS file or a tls/ listener without its
    certificate does not start, and the log names the option."""
    from bridge_server.zenoh.relay import main

    cert = tmp_path / "cert.pem"
    cert.write_text("")
    for argv, words in (
        ([], "no Zenoh endpoint: give --zenoh-connect or --zenoh-listen"),
        (["--zenoh-listen", "tcp/127.0.0.1:7447", "--zenoh-tls-ca", str(tmp_path / "no.pem")],
         f"--zenoh-tls-ca {tmp_path / 'no.pem'}: not a readable file"),
        (["--zenoh-listen", "tls/127.0.0.1:7447"], "a tls/ or quic/ --zenoh-listen endpoint "
         "needs --zenoh-tls-cert and --zenoh-tls-key"),
        (["--zenoh-listen", "tcp/127.0.0.1:7447", "--zenoh-tls-cert", str(cert)],
         "--zenoh-tls-cert and --zenoh-tls-key go together"),
    ):
        caplog.clear()
        assert main(["--port", "0", *argv]) == 1, argv
        assert any(words in r.getMessage() for r in caplog.records), (argv, caplog.text)


async def test_a_restarted_robot_is_watched_again(ros_node: Any, topic: str) -> None:
    """The robot's bridge stops and starts again (a new exporter run, numbering from 1): it
    finds the relay's demand still there and subscribes again, and the client that stayed
    connected gets the latched topic's last message again, though the relay had taken higher
    numbers from the robot's first run."""
    from rclpy.qos import DurabilityPolicy, QoSProfile

    from tests.relay.support import start_robot

    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)  # type: ignore[no-untyped-call]
    pub = ros_node.create_publisher(String, topic, latched)
    pub.publish(String(data="m1"))
    async with tier() as t:
        ws = await open_wire(t.url())
        try:
            await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String"})
            assert (await ws.expect(op="publish", topic=topic, timeout=20))["msg"]["data"] == "m1"
            for n in range(2, 6):  # the first run numbers these 2..5
                pub.publish(String(data=f"m{n}"))
                op = await ws.expect(op="publish", topic=topic)
                assert op["msg"]["data"] == f"m{n}"
            await t.exporter.close()
            await t.robot.close()
            t.robot, t.exporter = await start_robot(t.router)
            op = await ws.expect(op="publish", topic=topic, timeout=20)  # number 1 of the new run
            assert op["msg"] == {"data": "m5"}
        finally:
            await ws.close()
