"""Each robot's types are its own on a relay (msgs.dynamic.TypeStore per robot): two robots
may define one name differently, a robot's huge definition costs its samples nothing per
sample, a robot over the relay's limits is refused by name, and a robot's types go when it
has left and no client uses them. Robot1 is a real rclpy bridge; the others are played by a
plain Zenoh session (tests/relay/support.py), which makes a malicious robot easy."""

from __future__ import annotations

import asyncio
import contextlib
import gc
import logging
import re
import sys
import weakref
from typing import Any

import pytest

from bridge_server.foxglove.hub import message_class
from bridge_server.zenoh import keys
from bridge_server.zenoh.graph import TypeLimits
from bridge_server.zenoh.keys import Snapshot
from msgs import cdr
from msgs.dynamic import DELIMITER, TypeStore
from tests.helpers import open_wire, ros_env
from tests.ops.support import aget
from tests.relay.procs import Proc
from tests.relay.support import (
    free_port,
    played_robot,
    robot_reachable,
    start_relay,
    start_robot,
    until,
)
from tests.relay.test_relay import _first

pytestmark = pytest.mark.timeout(90)

STATUS = "robot_msgs/msg/Status"
THEIRS = "string hijacked_field\nint32 mode\n"
"""robot2's own robot_msgs/msg/Status: the name robot1 (rclpy, tests/interfaces) also has."""


def _rss_mb() -> float:
    """This process's resident memory in MB (for the report; never asserted)."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096 / 1e6


async def test_two_robots_each_get_their_own_layout_of_one_type_name(ros_node: Any,
                                                                      topic: str) -> None:
    """robot2 defines robot_msgs/msg/Status its own way first; robot1 (rclpy) has the real
    one: each robot's clients get that robot's layout, and a client's publish to each is
    encoded in that robot's layout (rclpy reads robot1's; robot2's bytes decode with its);
    rosapi's full texts and the Foxglove hub's classes are each robot's own."""
    from robot_msgs.msg import Status, Wheel

    theirs: Any = TypeStore("robot2 as this test knows it").load(STATUS, THEIRS)
    router = f"tcp/127.0.0.1:{free_port()}"
    relay = await start_relay(listen=router)
    bridge, exporter = await start_robot(router, robot="robot1")
    snap = Snapshot(node="robot2_bridge", topics=[(topic, [STATUS])],
                    definitions={STATUS: THEIRS})
    commands = topic + "_cmd"
    heard: list[bytes] = []
    clients: list[Any] = []
    try:
        async with played_robot(relay, router, "robot2", snap) as robot2:
            listener = robot2.session.declare_subscriber(
                keys.key_of("robot2", commands, keys.IN), lambda s: heard.append(
                    s.payload.to_bytes()))
            await robot_reachable(relay, "robot1")
            ws2 = await open_wire(f"ws://127.0.0.1:{relay.port}/robot2")
            ws1 = await open_wire(f"ws://127.0.0.1:{relay.port}/robot1")
            clients += [ws1, ws2]
            await ws2.send({"op": "subscribe", "topic": topic, "type": STATUS})
            seq = iter(range(1, 10_000))
            got2 = await _first(ws2, lambda: robot2.put(
                topic, cdr.encode(theirs(hijacked_field="mine", mode=7)), STATUS, next(seq)),
                topic)
            assert got2["msg"] == {"hijacked_field": "mine", "mode": 7}

            pub = ros_node.create_publisher(Status, topic, 10)
            graph1: Any = relay.robots["robot1"].graph
            await until(lambda: STATUS in graph1.snapshot.definitions, "robot1's definition")
            await ws1.send({"op": "subscribe", "topic": topic, "type": STATUS})
            got1 = await _first(ws1, lambda: pub.publish(Status(
                mode=1, label="rover", wheels=[Wheel(name="left", ticks=[1, 2, 3])])), topic)
            assert got1["msg"]["label"] == "rover" and "hijacked_field" not in got1["msg"]
            assert got1["msg"]["wheels"][0]["ticks"] == [1, 2, 3]

            await ws2.send({"op": "advertise", "topic": commands, "type": STATUS})
            await ws2.send({"op": "publish", "topic": commands,
                            "msg": {"hijacked_field": "to robot2", "mode": 9}})
            await until(lambda: heard, "robot2's command")
            assert theirs.from_json(cdr.decode(heard[0], theirs)) == theirs(
                hijacked_field="to robot2", mode=9)

            ros_got: list[Any] = []
            ros_node.create_subscription(Status, commands, ros_got.append, 10)
            await ws1.send({"op": "advertise", "topic": commands, "type": STATUS})
            n = 0
            while not ros_got:  # until the robot's publisher matched the rclpy subscriber
                n += 1
                await ws1.send({"op": "publish", "topic": commands,
                                "msg": {"label": "to robot1", "mode": 1}})
                assert n < 200, "nothing reached robot1's ROS"
                await asyncio.sleep(0.1)
            assert (ros_got[0].label, ros_got[0].mode) == ("to robot1", 1)
            listener.undeclare()

            texts = {}  # how each robot's clients see the type described
            for name, ws in (("robot2", ws2), ("robot1", ws1)):
                await ws.send({"op": "call_service", "service": "/rosapi/topics_and_raw_types",
                               "id": "raw"})
                values = (await ws.expect(op="service_response", id="raw"))["values"]
                texts[name] = values["typedefs_full_text"][values["topics"].index(topic)]
                foxglove = message_class(relay.robots[name].graph, STATUS)  # Foxglove's CDR
                assert ("hijacked_field" in foxglove._fields_and_types) == (name == "robot2")
            assert texts["robot2"] == THEIRS and "label" in texts["robot1"]
    finally:
        for ws in clients:
            await ws.close()
        await relay.close()
        await exporter.close()
        await bridge.close()


async def test_a_robot_that_redefines_a_type_is_read_with_its_new_definition(
        topic: str, caplog: pytest.LogCaptureFixture) -> None:
    """robot2 sends a new graph with another definition of the type its topic carries: the
    next message is read in the new layout (the relay keeps a topic's converter between
    messages, never across a new definition), and a client's publish to robot2 is encoded in
    it, through the publisher it advertised before."""
    new_text = "int32 mode\nstring renamed_field\n"
    theirs: Any = TypeStore("robot2's first layout").load(STATUS, THEIRS)
    renamed: Any = TypeStore("robot2's second layout").load(STATUS, new_text)
    router = f"tcp/127.0.0.1:{free_port()}"
    relay = await start_relay(listen=router)
    snap = Snapshot(node="robot2_bridge", topics=[(topic, [STATUS])],
                    definitions={STATUS: THEIRS})
    ws = None
    try:
        async with played_robot(relay, router, "robot2", snap) as robot2:
            graph: Any = relay.robots["robot2"].graph
            ws = await open_wire(f"ws://127.0.0.1:{relay.port}/robot2")
            await ws.send({"op": "subscribe", "topic": topic, "type": STATUS})
            seq = iter(range(1, 10_000))
            got = await _first(ws, lambda: robot2.put(
                topic, cdr.encode(theirs(hijacked_field="first", mode=1)), STATUS, next(seq)),
                topic)
            assert got["msg"] == {"hijacked_field": "first", "mode": 1}
            commands = topic + "_cmd"
            heard: list[bytes] = []
            listener = robot2.session.declare_subscriber(
                keys.key_of("robot2", commands, keys.IN),
                lambda sample: heard.append(sample.payload.to_bytes()))
            await ws.send({"op": "advertise", "topic": commands, "type": STATUS})
            while not heard:  # until the robot's subscriber matched the relay's puts
                await ws.send({"op": "publish", "topic": commands,
                               "msg": {"hijacked_field": "old", "mode": 4}})
                await asyncio.sleep(0.1)
            assert theirs.from_json(cdr.decode(heard[0], theirs)).mode == 4
            robot2.put(topic, cdr.encode(theirs(hijacked_field="again", mode=2)), STATUS,
                       next(seq))  # read with the converter kept from the first
            while (await ws.expect(op="publish", topic=topic))["msg"]["mode"] != 2:
                pass
            second = Snapshot(node="robot2_bridge", topics=[(topic, [STATUS])],
                              definitions={STATUS: new_text})
            robot2.snapshot = second
            robot2.session.put(f"robot2/{keys.GRAPH}", second.encode())
            await until(lambda: graph.snapshot.definitions.get(STATUS) == new_text,
                        "robot2's new graph")
            robot2.put(topic, cdr.encode(renamed(mode=3, renamed_field="second")), STATUS,
                       next(seq))
            msg = (await ws.expect(op="publish", topic=topic))["msg"]
            assert msg == {"mode": 3, "renamed_field": "second"}
            heard.clear()
            await ws.send({"op": "publish", "topic": commands,
                           "msg": {"mode": 5, "renamed_field": "new"}})
            await until(lambda: heard, "the publish in the new layout")
            back = renamed.from_json(cdr.decode(heard[0], renamed))
            assert (back.mode, back.renamed_field) == (5, "new")
            assert f"robot robot2: its definition of {STATUS} changed" in caplog.text
            listener.undeclare()
    finally:
        if ws is not None:
            await ws.close()
        await relay.close()


def _big_definition(size: int) -> str:
    """flood_msgs/msg/Big: one int32 (8 bytes of CDR) under ``size`` bytes of short comment
    lines (what splitting a text costs most)."""
    return "int32 value\n" + "# pad\n" * (size // 6)


@pytest.mark.parametrize("case", ["1.2 MB, refused by the default limit",
                                  "1.2 MB, within a raised limit",
                                  "250 KB that do not parse, within the default limit"])
async def test_a_robots_huge_definition_does_not_slow_another_robots_viewer(
        ros_node: Any, topic: str, case: str) -> None:
    """A relay process; a played robot with a huge definition puts 5 of its 8-byte samples
    for every message of robot1's 10/s topic: robot1's viewer gets at least 90 % of the 40
    messages and stays connected (refused: the relay says so once; raised: its client gets
    the samples; one that does not parse: the relay says why once)."""
    from std_msgs.msg import String

    big = _big_definition(1_200_000 if case.startswith("1.2") else 250_000)
    big_cls: Any = TypeStore("the flooder as this test knows it").load("flood_msgs/msg/Big", big)
    raised = "raised" in case
    if "parse" in case:
        big += "float77 broken\n"
    router = f"tcp/127.0.0.1:{free_port()}"
    argv = [sys.executable, "-m", "bridge_server.zenoh.relay", "--port", "0",
            "--zenoh-listen", router] + (["--max-definition-bytes", "2000000"] if raised else [])
    proc = Proc(argv, ros_env())
    bridge, exporter = await start_robot(router, robot="robot1")
    snap = Snapshot(node="flood_bridge", definitions={"flood_msgs/msg/Big": big})
    clients: list[Any] = []
    try:
        port = int(proc.wait_for(re.compile(r"relay listening on ws://127\.0\.0\.1:(\d+)"))
                   .group(1))
        async with played_robot(None, router, "flooder", snap) as flooder:
            deadline = asyncio.get_running_loop().time() + 20
            while True:  # until both robots' liveliness reached the relay: 404 till then
                try:
                    viewer = await open_wire(f"ws://127.0.0.1:{port}/robot1")
                    clients.append(viewer)
                    flood_client = await open_wire(f"ws://127.0.0.1:{port}/flooder")
                    clients.append(flood_client)
                    break
                except Exception:
                    assert asyncio.get_running_loop().time() < deadline, "robots never served"
                    await asyncio.sleep(0.1)
            # not in the robot's graph: the relay takes each sample's type from its Meta
            await flood_client.send({"op": "subscribe", "topic": "/flood"})
            pub = ros_node.create_publisher(String, topic, 10)
            await viewer.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String"})
            await _first(viewer, lambda: pub.publish(String(data="hello")), topic)
            sample = cdr.encode(big_cls(value=1))
            assert len(sample) == 8
            received: list[str] = []

            async def count() -> None:
                while True:
                    op = await viewer.expect(op="publish", topic=topic, timeout=30)
                    received.append(op["msg"]["data"])

            counting = asyncio.ensure_future(count())
            seq = 0
            for i in range(40):
                pub.publish(String(data=f"tick {i}"))
                for _ in range(5):
                    seq += 1
                    flooder.put("/flood", sample, "flood_msgs/msg/Big", seq)
                await asyncio.sleep(0.1)  # robot1's rate: 10 messages a second
            with contextlib.suppress(AssertionError):  # what is on its way (not a measure)
                await until(lambda: "tick 39" in received, "tick 39", timeout=3)
            counting.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await counting
            ticks = [t for t in received if t.startswith("tick ")]
            assert len(ticks) >= 36, f"robot1's viewer got {len(ticks)} of 40"
            await viewer.send({"op": "call_service", "service": "/rosapi/topics", "id": "up"})
            await viewer.expect(op="service_response", id="up")  # still connected
            if raised:
                got = await flood_client.expect(op="publish", topic="/flood")
                assert got["msg"] == {"value": 1}
            elif "parse" in case:
                proc.wait_for(re.compile(r"robot flooder: messages of /flood dropped: .*"
                                         r"does not build .*float77"))
            else:
                proc.wait_for(re.compile(r"robot flooder: type flood_msgs/msg/Big refused: .*"
                                         r"--max-definition-bytes"))
    finally:
        for ws in clients:
            await ws.close()
        proc.stop()
        await exporter.close()
        await bridge.close()


def _many_definition(count: int) -> str:
    """many_msgs/msg/Top with ``count`` nested types of its own, each defined after it."""
    top = "".join(f"many_msgs/T{i} t{i}\n" for i in range(count))
    deps = "".join(f"{DELIMITER}\nMSG: many_msgs/msg/T{i}\nint32 a\nstring[] b\n"
                   for i in range(count))
    return top + deps


async def test_a_robots_types_go_when_it_left_and_no_client_uses_them(topic: str) -> None:
    """A robot's 901 types stay while a client of the relay subscribes, though the robot
    left; once the client unsubscribes they are released: the robot's store is empty and the
    old one's modules are gone (RSS printed, not asserted)."""
    top = "many_msgs/msg/Top"
    router = f"tcp/127.0.0.1:{free_port()}"
    relay = await start_relay(listen=router)
    snap = Snapshot(node="many_bridge", topics=[(topic, [top])],
                    definitions={top: _many_definition(900)})
    ws = None
    try:
        async with played_robot(relay, router, "many", snap) as robot:
            gc.collect()
            before = _rss_mb()
            graph: Any = relay.robots["many"].graph
            ws = await open_wire(f"ws://127.0.0.1:{relay.port}/many")
            await ws.send({"op": "subscribe", "topic": topic, "type": top, "id": "s"})
            await until(lambda: topic in graph.subscriptions, "the relay's subscription")
            assert len(graph.wire_types) == 901
            loaded = _rss_mb()
            store = weakref.ref(graph.wire_types)
            root = graph.wire_types._root
            robot.leave()
            await until(lambda: not graph.alive, "the robot to leave")
            assert len(graph.wire_types) == 901  # a client still uses them
            await ws.send({"op": "unsubscribe", "topic": topic, "id": "s"})
            await until(lambda: topic not in graph.subscriptions, "the unsubscribe")
            assert len(graph.wire_types) == 0
            assert not [m for m in sys.modules if m.startswith(root)]
            gc.collect()
            print(f"\nRSS {before:.1f} MB, with 901 types {loaded:.1f} MB, released "
                  f"{_rss_mb():.1f} MB (old store collected: {store() is None})")
    finally:
        if ws is not None:
            await ws.close()
        await relay.close()


async def test_a_robot_over_the_relays_type_limits_is_refused_by_name(
        topic: str, caplog: pytest.LogCaptureFixture) -> None:
    """A relay taking 16 KB definitions and 50 types per robot: a robot's 20 KB definition and
    its 60-type one are refused (its client is told which limit, the log names the robot
    and the limit once), its samples of them are dropped and counted (/metrics too), and its
    small type still works."""
    caplog.set_level(logging.WARNING)
    router = f"tcp/127.0.0.1:{free_port()}"
    relay = await start_relay(listen=router,
                              type_limits=TypeLimits(definition_bytes=16384, types=50))
    wide, big, small = "greedy_msgs/msg/Wide", "greedy_msgs/msg/Big", "greedy_msgs/msg/Small"
    snap = Snapshot(node="greedy_bridge", definitions={
        wide: _many_definition(60).replace("many_msgs", "greedy_msgs").replace("/Top", "/Wide"),
        big: _big_definition(20_000), small: "int32 value\n"})
    ws = None
    try:
        async with played_robot(relay, router, "greedy", snap) as robot:
            graph: Any = relay.robots["greedy"].graph
            ws = await open_wire(f"ws://127.0.0.1:{relay.port}/greedy")
            for name, option in ((big, "--max-definition-bytes"),
                                 (wide, "--max-types-per-robot")):
                await ws.send({"op": "subscribe", "topic": topic + "_x", "type": name})
                error = await ws.expect(op="status", level="error")
                assert name in error["msg"] and option in error["msg"], error
                assert [r for r in caplog.records if re.search(
                    f"robot greedy: type {name} refused: .*{option}", r.getMessage())]
            await ws.send({"op": "subscribe", "topic": "/unlisted"})
            small_cls: Any = TypeStore("greedy as this test knows it").load(small, "int32 value\n")
            seq = iter(range(1, 10_000))

            def put_both() -> None:
                robot.put("/unlisted", b"\x00\x01\x00\x00\x05\x00\x00\x00", big, next(seq))
                robot.put("/unlisted", cdr.encode(small_cls(value=5)), small, next(seq))

            got = await _first(ws, put_both, "/unlisted")
            assert got["msg"] == {"value": 5}
            dropped = graph.faults.counts.get("type_refused", 0)
            put_both()  # in order: the refused one is taken before the small one comes
            assert (await ws.expect(op="publish", topic="/unlisted"))["msg"] == {"value": 5}
            assert graph.faults.counts.get("type_refused", 0) == dropped + 1, graph.faults.counts
            _, _, scraped = await aget(f"http://127.0.0.1:{relay.port}/metrics")
            assert (f'roslibpy_relay_robot_dropped_total{{kind="type_refused",robot="greedy"}}'
                    f" {dropped + 1}.0") in scraped.decode()
            assert len(graph.wire_types) == 1  # the small one; nothing of the refused ones
            said = [r for r in caplog.records if ": type greedy_msgs/" in r.getMessage()]
            assert len(said) == 2, [r.getMessage() for r in said]  # once per limit
    finally:
        if ws is not None:
            await ws.close()
        await relay.close()

