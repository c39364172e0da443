"""The stock Foxglove client reading slowly, time from /clock, and what SIGHUP changes for a role."""

from __future__ import annotations

import functools
import time
from pathlib import Path
from typing import Any

from tests.helpers import BridgeProcess, wait_until
from tests.peers import scenarios
from tests.peers.foxglove.support import (
    DEADLINE,
    _all_sent,
    _as,
    _bridge_received,
    _graph_topics,
    _published_by,
    _ReloadedRoles,
    _status,
    _wait_error,
)
from tests.peers.peer import PeerProcess, foxglove_peer

# -- slow clients, time ----------------------------------------------------------------------------


def test_slow_client_gets_the_newest_frames(bridge: BridgeProcess, ros_node: Any,
                                            topic: str) -> None:
    """A Foxglove client that stops reading while 60 camera frames (640x480 rgb8) go through
    the bridge is sent the newest ones when it reads again, not a backlog of all 60: the
    older ones are dropped and it is told so."""
    import json

    from sensor_msgs.msg import Image
    from websockets.sync.client import connect
    from websockets.typing import Subprotocol

    from msgs import cdr
    from msgs.runtime import lookup_message

    image_cls = lookup_message("sensor_msgs/msg/Image")
    pub = ros_node.create_publisher(Image, topic, 10)
    img = Image(height=480, width=640, encoding="rgb8", step=1920, data=bytes(640 * 480 * 3))
    # max_queue=1: the client library itself holds at most one frame it was not asked for
    with connect(bridge.url, subprotocols=[Subprotocol("foxglove.websocket.v1")], max_size=None,
                 max_queue=1, open_timeout=DEADLINE) as ws:
        channel = None
        while channel is None:
            frame = ws.recv(DEADLINE)
            if isinstance(frame, str) and json.loads(frame)["op"] == "advertise":
                channel = next((c for c in json.loads(frame)["channels"]
                                if c["topic"] == topic), None)
        ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 7,
                                                                 "channelId": channel["id"]}]}))
        deadline = time.monotonic() + DEADLINE
        while True:  # one frame through, so the bridge's subscription is matched
            img.header.frame_id = "first"
            pub.publish(img)
            try:
                frame = ws.recv(scenarios.ATTEMPT)
            except TimeoutError:
                assert time.monotonic() < deadline, "no first frame"
                continue
            if isinstance(frame, bytes):
                break
        while True:  # drain what else the first publishes sent
            try:
                ws.recv(1.0)
            except TimeoutError:
                break
        received = _status(bridge)["topics"][topic]["ros_received"]
        for i in range(60):  # the client reads nothing meanwhile
            img.header.frame_id = str(i)
            pub.publish(img)
            wait_until(functools.partial(_bridge_received, bridge, topic, received + i + 1),
                       DEADLINE, f"the bridge to receive frame {i}")
        numbers: list[int] = []
        warnings: list[str] = []
        while not numbers or numbers[-1] != 59:
            frame = ws.recv(DEADLINE)
            if isinstance(frame, bytes):
                assert frame[0] == 1 and int.from_bytes(frame[1:5], "little") == 7
                numbers.append(int(cdr.decode(frame[13:], image_cls)["header"]["frame_id"]))
            elif json.loads(frame)["op"] == "status":
                warnings.append(json.loads(frame)["message"])
    assert numbers == sorted(numbers)
    assert len(numbers) < 45, f"a backlog was sent: {numbers}"
    assert any(f"on {topic}" in w and "dropped" in w for w in warnings), warnings


def test_time_from_clock(make_bridge: Any, ros_node: Any, topic: str) -> None:
    """With /clock published, the first Foxglove client of a bridge is offered 'time' and
    sent the clock's value."""
    from rosgraph_msgs.msg import Clock  # type: ignore[import-untyped]

    clock = ros_node.create_publisher(Clock, "/clock", 10)
    try:
        bridge = make_bridge()
        wait_until(lambda: "/clock" in _graph_topics(bridge), DEADLINE, "/clock in the graph")
        peer = foxglove_peer(bridge.url, bridge)
        try:
            assert "time" in peer.info["serverInfo"]["capabilities"]
            msg = Clock()
            msg.clock.sec, msg.clock.nanosec = 1234, 5678
            deadline = time.monotonic() + DEADLINE
            event = None
            while event is None and time.monotonic() < deadline:
                clock.publish(msg)
                try:
                    event = peer.wait_event(lambda e: e.get("event") == "time",
                                            scenarios.ATTEMPT, "time")
                except AssertionError:
                    continue
            assert event is not None, peer.diagnostics()
            assert event["timestamp"] == {"$bigint": str(1234 * 10**9 + 5678)}
        finally:
            peer.close()
    finally:
        ros_node.destroy_publisher(clock)


def test_time_only_for_roles_that_may_subscribe_clock(secured: tuple[BridgeProcess, Any],
                                                      ros_node: Any) -> None:
    """With /clock published, a role that may not subscribe to /clock is not offered 'time' and
    gets no tick, while an admin client is offered it and gets the ticks."""
    from rosgraph_msgs.msg import Clock

    clock = ros_node.create_publisher(Clock, "/clock", 10)
    try:
        tester = _as(secured, "tester")  # it may subscribe to anything: it is told of /clock
        try:
            tester.request("wait_channel", topic="/clock", timeout_ms=int(DEADLINE * 1000))
        finally:
            tester.close()
        admin, prober = _as(secured, "admin"), _as(secured, "prober")
        try:
            assert "time" in admin.info["serverInfo"]["capabilities"]
            assert "time" not in prober.info["serverInfo"]["capabilities"]
            msg = Clock()
            msg.clock.sec = 4321
            deadline = time.monotonic() + DEADLINE
            while True:  # until the bridge's /clock reader is matched
                clock.publish(msg)
                try:
                    admin.wait_event(lambda e: e.get("event") == "time", scenarios.ATTEMPT,
                                     "time")
                    break
                except AssertionError:
                    assert time.monotonic() < deadline, admin.diagnostics()
            assert not [e for e in _all_sent(prober) if e.get("event") == "time"]
        finally:
            admin.close()
            prober.close()
    finally:
        ros_node.destroy_publisher(clock)


def test_sighup_brings_channels_and_services_to_the_role(tmp_path: Path, ros_node: Any,
                                                         topic: str) -> None:
    """When SIGHUP takes a topic and a service from a role, its Foxglove client is told they
    went (unadvertise, unadvertiseServices); when a later SIGHUP gives them back, they are
    advertised again with the same ids."""
    from std_msgs.msg import String
    from std_srvs.srv import SetBool

    ros_node.create_publisher(String, topic, 10)
    ros_node.create_service(SetBool, topic + "_srv", lambda req, res: res)
    allowed = 'subscribe = ["*"]\ncall_service = ["*"]\n'
    roles = _ReloadedRoles(tmp_path, allowed)
    try:
        dora = roles.connect("dora")
        channel = dora.request("wait_channel", topic=topic, timeout_ms=int(DEADLINE * 1000))
        service = dora.request("service", service=topic + "_srv",
                               timeout_ms=int(DEADLINE * 1000))
        line = roles.reload(allowed + f'deny.subscribe = ["{topic}"]\n'
                            f'deny.call_service = ["{topic}_srv"]\n')
        assert "0 grant(s)" in line  # nothing it held ended: it was only told of them
        dora.wait_event(lambda e: e.get("event") == "unadvertise"
                        and channel["id"] in e["channelIds"], DEADLINE, "unadvertise")
        dora.wait_event(lambda e: e.get("event") == "unadvertiseServices"
                        and service["id"] in e["serviceIds"], DEADLINE, "unadvertiseServices")
        roles.reload(allowed)

        def told(kind: str, key: str, id: int) -> int:
            return sum(1 for e in dora.new_events() if e.get("event") == kind
                       and any(x["id"] == id for x in e[key]))

        wait_until(lambda: told("advertise", "channels", channel["id"]) == 2, DEADLINE,
                   "the channel advertised again")
        wait_until(lambda: told("advertiseServices", "services", service["id"]) == 2,
                   DEADLINE, "the service advertised again")
    finally:
        roles.close()


def test_sighup_ends_time_and_narrows_the_graph(tmp_path: Path, ros_node: Any,
                                                topic: str) -> None:
    """After SIGHUP takes /clock and most introspection from a role, its Foxglove client hears
    that time ended and gets no more ticks (a client of another role still does), and its
    connection graph drops what it may no longer see; when introspection goes too, graph
    updates end. The client hears each."""
    from rosgraph_msgs.msg import Clock
    from std_msgs.msg import String

    clock = ros_node.create_publisher(Clock, "/clock", 10)
    ros_node.create_publisher(String, topic, 10)
    roles = _ReloadedRoles(tmp_path, 'subscribe = ["*"]\nintrospection = ["*"]\n')
    try:
        roles.connect("root").request("wait_channel", topic="/clock",
                                      timeout_ms=int(DEADLINE * 1000))
        dora, root = roles.connect("dora"), roles.connect("root")
        assert "time" in dora.info["serverInfo"]["capabilities"]
        dora.request("subscribe_graph")
        dora.wait_event(_published_by(topic, ros_node.get_fully_qualified_name()), DEADLINE,
                        "the topic in the graph")

        def tick(sec: int) -> None:
            """Publish /clock until root has the tick (so dora's would have been sent too)."""
            msg = Clock()
            msg.clock.sec = sec
            deadline = time.monotonic() + DEADLINE
            while True:
                clock.publish(msg)
                try:
                    root.wait_event(lambda e: e.get("event") == "time" and e["timestamp"] == {
                        "$bigint": str(sec * 10**9)}, scenarios.ATTEMPT, f"tick {sec}")
                    return
                except AssertionError:
                    assert time.monotonic() < deadline, root.diagnostics()

        def ticks(peer: PeerProcess) -> list[int]:
            return [int(e["timestamp"]["$bigint"]) // 10**9 for e in _all_sent(peer)
                    if e.get("event") == "time"]

        tick(1)
        assert 1 in ticks(dora)
        assert "1 grant(s) the new roles no longer allow ended" in roles.reload(
            'subscribe = ["*"]\nintrospection = ["/seen*"]\ndeny.subscribe = ["/clock"]\n')
        _wait_error(dora, "time from /clock ended: role watcher may not subscribe on /clock")
        dora.wait_event(lambda e: e.get("event") == "connectionGraphUpdate"
                        and topic in e["update"]["removedTopics"], DEADLINE,
                        "the topic removed from the graph")
        tick(2)
        assert 2 not in ticks(dora)
        assert "1 grant(s) the new roles no longer allow ended" in roles.reload(
            'subscribe = ["*"]\ndeny.subscribe = ["/clock"]\n')
        _wait_error(dora, "connection graph updates ended: role watcher may not introspection "
                          "on any name")
    finally:
        roles.close()
        ros_node.destroy_publisher(clock)
