"""Actions through the relay tier (tests/relay/support.py): a relay client's goal reaches an
rclpy action server on the robot, with feedback and the result coming back; a cancel, the
client's leaving and the relay's death each cancel the goal on the robot. And the other way:
a relay client serves an action that an rclpy action client on the robot uses."""

from __future__ import annotations

import asyncio
import importlib
from pathlib import Path
from typing import Any

import pytest

from bridge_server.front.server import BridgeConfig
from bridge_server.zenoh.graph import ZenohGraph
from bridge_server.zenoh.link import ZenohOptions
from bridge_server.zenoh.relay import Relay
from rosbridge_core.security import SecurityConfig
from tests.bridge.action_support import FIB, FibServer, RosCaller, fib
from tests.helpers import open_wire
from tests.relay.support import (
    ROBOT,
    Tier,
    free_port,
    robot_reachable,
    start_robot,
    tier,
    until,
)

pytestmark = pytest.mark.timeout(90)

_action: Any = importlib.import_module("rclpy.action")  # untyped API, used as Any
RCLError: Any = importlib.import_module("rclpy._rclpy_pybind11").RCLError


async def _relay_lists(t: Tier, action: str) -> None:
    """Wait until the relay's graph of the robot lists ``action``'s server."""
    graph = t.relay.robots[ROBOT].graph
    await until(lambda: graph.server_types(action + "/_action/send_goal"),
                f"the relay to list the action server of {action}")


async def _goal_with_feedback(t: Tier, ws: Any, action: str, gid: str) -> dict[str, Any]:
    """Send an order-3 Fibonacci goal ``gid`` once the relay lists ``action``'s server and
    await its first feedback; the goal's op, for more goals like it."""
    await _relay_lists(t, action)
    goal = {"op": "send_action_goal", "action": action, "action_type": FIB,
            "args": {"order": 3}, "feedback": True}
    await ws.send({**goal, "id": gid})
    await ws.expect(op="action_feedback", id=gid, timeout=20)
    return goal


async def _succeeds(ws: Any, goal: dict[str, Any], gid: str) -> None:
    """Send ``goal`` (order 3) as ``gid`` and see it succeed with its sequence."""
    await ws.send({**goal, "id": gid})
    result = await ws.expect(op="action_result", id=gid, timeout=20)
    assert result["status"] == 4 and result["values"] == {"sequence": fib(3)}, result


async def test_a_goal_gets_feedback_and_its_result(ros_node: Any, topic: str) -> None:
    """A relay client's goal runs on an rclpy action server on the robot: its feedback and
    result (SUCCEEDED, the sequence) come back as on the bridge; a goal that does not fit the
    type is refused by the relay with the field named."""
    server = FibServer(ros_node, topic)
    try:
        async with tier() as t:
            ws = await open_wire(t.url())
            try:
                await _relay_lists(t, topic)
                await ws.send({"op": "send_action_goal", "action": topic, "action_type": FIB,
                               "args": {"order": 5}, "feedback": True, "id": "g1"})
                feedback = await ws.expect(op="action_feedback", id="g1", timeout=20)
                assert feedback["values"]["sequence"][:2] == [0, 1], feedback
                result = await ws.expect(op="action_result", id="g1", timeout=20)
                assert result["status"] == 4 and result["result"] is True, result
                assert result["values"] == {"sequence": fib(5)}
                assert server.goals == [5]

                await ws.send({"op": "send_action_goal", "action": topic, "action_type": FIB,
                               "args": {"order": "five"}, "id": "g2"})
                error = await ws.expect(op="status", level="error", id="g2")
                assert "args.order" in error["msg"], error
                assert server.goals == [5]
            finally:
                await ws.close()
    finally:
        server.destroy()


async def test_cancel_and_leaving_cancel_the_goal_on_the_robot(ros_node: Any, topic: str
                                                               ) -> None:
    """cancel_action_goal cancels the goal on the robot's action server (the client gets
    CANCELED); a client that disconnects, and a relay that dies, take their goals with them:
    the robot cancels each."""
    server = FibServer(ros_node, topic, slow=True)
    try:
        async with tier() as t:
            ws = await open_wire(t.url())
            await _relay_lists(t, topic)
            goal = {"op": "send_action_goal", "action": topic, "action_type": FIB,
                    "args": {"order": 3}, "feedback": True}
            await ws.send({**goal, "id": "c1"})
            await ws.expect(op="action_feedback", id="c1", timeout=20)
            await ws.send({"op": "cancel_action_goal", "action": topic, "id": "c1"})
            result = await ws.expect(op="action_result", id="c1", timeout=20)
            assert result["status"] == 5, result
            assert server.cancel_requests.is_set()

            for leaving in ("the client", "the relay"):
                server.cancel_requests.clear()
                ws = await open_wire(t.url())
                await ws.send({**goal, "id": "c2"})
                await ws.expect(op="action_feedback", id="c2", timeout=20)
                assert not server.cancel_requests.is_set()
                if leaving == "the client":
                    await ws.close()
                else:
                    await t.relay.close()
                    await ws.close()
                await until(server.cancel_requests.is_set,
                            f"the robot to cancel the goal of {leaving} that went")
                await until(lambda: not t.exporter.goals, "the robot to forget the goal")
    finally:
        server.destroy()


async def test_the_robot_names_what_is_wrong_with_a_request(topic: str) -> None:
    """A goal, call or parameter query whose payload is not what the wire contract says gets
    an answer naming what is wrong (a plain Zenoh session plays a faulty relay)."""
    from bridge_server.zenoh import keys
    from bridge_server.zenoh.keys import CallRequest, GoalEvent, GoalRequest
    from bridge_server.zenoh.link import ZenohOptions, open_session

    async with tier() as t:
        session = await open_session(ZenohOptions(connect=[t.router]))
        try:
            def ask(key: str, payload: bytes) -> list[Any]:
                return [r.ok.payload.to_bytes() if r.ok else r.err.payload.to_string()  # type: ignore[union-attr]
                        for r in session.get(key, payload=payload, timeout=10)]

            replies = await asyncio.to_thread(ask, f"{ROBOT}/{keys.GOAL}/r{topic}",
                                              b'{"goal": 1}')
            event = GoalEvent.decode(replies[0])
            assert event.event == "failed" and "is not a GoalRequest" in event.text, event
            assert "'type'" in event.text
            replies = await asyncio.to_thread(ask, f"{ROBOT}/{keys.PARAM}/some_node",
                                              b'{"op": "drop"}')
            assert "op 'drop' is not one of names, get, set" in replies[0], replies
            replies = await asyncio.to_thread(
                ask, f"{ROBOT}/{keys.PARAM}/some_node",
                b'{"op": "set", "name": "blob", "value": "not base64!", "binary": true}')
            assert "binary value is not base64 text" in replies[0], replies

            # a wait that is not a number of seconds would make a deadline nothing reaches
            goal = GoalRequest(type="test_msgs/action/Fibonacci", goal={"order": 1},
                               feedback=False, relay="r", id="g", timeout=0.0).encode()
            nan = goal.replace(b'"timeout":0.0', b'"timeout":NaN')
            replies = await asyncio.to_thread(ask, f"{ROBOT}/{keys.GOAL}/r{topic}", nan)
            event = GoalEvent.decode(replies[0])
            assert event.event == "failed" and "timeout nan is not a number of seconds" in \
                event.text, event
            call = CallRequest(type=None, args={}, timeout=1.0, discovery_wait=-1.0).encode()
            replies = await asyncio.to_thread(ask, f"{ROBOT}/{keys.CALL}/r{topic}", call)
            assert "discovery_wait -1.0 is not a number of seconds" in replies[0], replies
            call = CallRequest(type="std_srvs/srv/Trigger", args={}, timeout=1.0,
                               discovery_wait=0.0).encode()
            replies = await asyncio.to_thread(ask, f"{ROBOT}/{keys.CALL}/r/9bad", call)
            assert "9bad" in replies[0] and "must not start with a number" in replies[0], replies
        finally:
            await asyncio.to_thread(session.close)


async def test_a_relay_client_serves_an_action_rclpy_uses(ros_node: Any, topic: str) -> None:
    """A relay client's advertise_action is served in ROS on the robot: an rclpy action
    client's goal reaches the relay client, whose feedback and result reach the caller; a ROS
    cancel reaches it as cancel_action_goal; when the relay dies the goal in flight is aborted
    and the action leaves ROS."""
    caller = RosCaller(ros_node, topic)
    try:
        async with tier() as t:
            ws = await open_wire(t.url())
            await ws.send({"op": "advertise_action", "action": topic, "type": FIB})
            await caller.ready(20)

            handle = await caller.send(3)
            goal = await ws.expect(op="send_action_goal", action=topic, timeout=20)
            assert goal["args"] == {"order": 3} and goal["action_type"] == FIB, goal
            await ws.send({"op": "action_feedback", "id": goal["id"], "action": topic,
                           "values": {"sequence": [0, 1]}})
            assert await asyncio.wait_for(caller.feedback.get(), 20) == [0, 1]
            await ws.send({"op": "action_result", "id": goal["id"], "action": topic,
                           "values": {"sequence": fib(3)}, "status": 4, "result": True})
            result = await caller.result(handle, 20)
            assert result.status == 4 and list(result.result.sequence) == fib(3)

            handle = await caller.send(4)
            goal = await ws.expect(op="send_action_goal", action=topic, timeout=20)
            canceling = handle.cancel_goal_async()
            await ws.expect(op="cancel_action_goal", id=goal["id"], timeout=20)
            await until(canceling.done, "the ROS caller's cancel to be answered")
            await ws.send({"op": "action_result", "id": goal["id"], "action": topic,
                           "values": {"sequence": [0]}, "status": 5, "result": True})
            result = await caller.result(handle, 20)
            assert result.status == 5 and list(result.result.sequence) == [0]

            handle = await caller.send(5)
            await ws.expect(op="send_action_goal", action=topic, timeout=20)
            await t.relay.close()
            result = await caller.result(handle, 20)  # asked after: the server lingers
            assert result.status == 6, result
            await until(lambda: not caller.client.server_is_ready(),
                        "the action to leave ROS with the relay")
            assert not t.exporter.served
            await ws.close()
    finally:
        caller.destroy()


async def test_a_goal_of_the_robots_own_action_type(ros_node: Any, topic: str) -> None:
    """An action type only the robot has (example_interfaces, which msgs does not generate)
    is built by the relay from the definition in the robot's graph: the goal, its feedback
    and result convert both ways."""
    from example_interfaces.action import Fibonacci

    own = "example_interfaces/action/Fibonacci"

    def execute(handle: Any) -> Any:
        handle.publish_feedback(Fibonacci.Feedback(sequence=[0, 1]))
        handle.succeed()
        return Fibonacci.Result(sequence=fib(handle.request.order))

    server = _action.ActionServer(ros_node, Fibonacci, topic, execute)
    try:
        async with tier() as t:
            ws = await open_wire(t.url())
            try:
                await _relay_lists(t, topic)
                graph = t.relay.robots[ROBOT].graph
                assert isinstance(graph, ZenohGraph) and own in graph.snapshot.definitions
                await ws.send({"op": "send_action_goal", "action": topic, "action_type": own,
                               "args": {"order": 4}, "feedback": True, "id": "own"})
                feedback = await ws.expect(op="action_feedback", id="own", timeout=20)
                assert feedback["values"] == {"sequence": [0, 1]}
                result = await ws.expect(op="action_result", id="own", timeout=20)
                assert result["status"] == 4 and result["values"] == {"sequence": fib(4)}
            finally:
                await ws.close()
    finally:
        server.destroy()


async def test_a_relay_client_cancels_only_its_own_goals(ros_node: Any, topic: str,
                                                         tmp_path: Path) -> None:
    """Through a relay with roles, as on the bridge: bob (send_action_goal only) cannot cancel
    every goal with a zero id through the action's cancel_goal service, and can cancel his own
    by its id (the robot told the relay the goal's id in ROS)."""
    from tests.security.test_cancel_goals import (
        CANCELED,
        _auth_file,
        _cancel_raw,
        _new_goal,
        _RecordingServer,
    )

    tokens = _auth_file(tmp_path)
    router = f"tcp/127.0.0.1:{free_port()}"
    relay = Relay(BridgeConfig(port=0, node_name="relay",
                               security=SecurityConfig(auth_file=str(tmp_path / "auth.toml"))),
                  ZenohOptions(listen=[router]))
    await relay.start()
    bridge, exporter = await start_robot(router)
    server = _RecordingServer(ros_node, topic)
    try:
        await robot_reachable(relay)
        url = f"ws://127.0.0.1:{relay.port}/{ROBOT}?token="
        alice, bob = await open_wire(url + tokens["alice"]), await open_wire(url + tokens["bob"])
        graph = relay.robots[ROBOT].graph
        await until(lambda: graph.server_types(topic + "/_action/send_goal"),
                    "the relay to list the action server")
        await bob.send({"op": "subscribe", "topic": topic + "/_action/status",
                        "type": "action_msgs/msg/GoalStatusArray"})
        await alice.send(_goal(topic, "a1"))
        await alice.expect(op="action_feedback", id="a1", timeout=20)
        alices = await _new_goal(bob, topic, set())
        reply = await _cancel_raw(bob, topic, bytes(16), "zero")
        assert reply["result"] is False and "forbidden" in reply["values"], reply
        await bob.send(_goal(topic, "b1"))
        await bob.expect(op="action_feedback", id="b1", timeout=20)
        bobs = await _new_goal(bob, topic, {alices})
        reply = await _cancel_raw(bob, topic, bobs, "mine")
        assert reply["result"] is True, reply
        assert (await bob.expect(op="action_result", id="b1", timeout=20))["status"] == CANCELED
        assert server.canceled == [bobs]
        await alice.close()
        await bob.close()
    finally:
        server.destroy()
        await relay.close()
        await exporter.close()
        await bridge.close()


def _goal(action: str, id: str) -> dict[str, Any]:
    return {"op": "send_action_goal", "action": action, "action_type": FIB,
            "args": {"order": 5}, "feedback": True, "id": id}


async def test_the_robot_destroys_an_action_client_no_goal_uses(ros_node: Any, topic: str
                                                                ) -> None:
    """The robot's action client of relays' goals is kept while a goal runs through it and
    destroyed once none used it for the idle time (as the bridge's are), leaving ROS; the
    next goal makes a new one."""
    server = FibServer(ros_node, topic, slow=True)
    try:
        async with tier() as t:
            t.exporter.client_idle = 0.3
            name, ns = t.robot.graph.own_node()

            def robot_clients() -> list[str]:  # an earlier test's robot had the same node name
                # rcl refuses a node this test's node has not discovered yet ("error not
                # set"): until it has, the robot has no action client this node can see
                if (name, ns) not in ros_node.get_node_names_and_namespaces():
                    return []
                try:
                    return [n for n, _ in _action.get_action_client_names_and_types_by_node(
                        ros_node, name, ns)]
                except RCLError:  # discovered, then gone between the two graph queries
                    return []

            ws = await open_wire(t.url())
            try:
                goal = await _goal_with_feedback(t, ws, topic, "i1")
                await until(lambda: topic in robot_clients(), "the robot's action client in ROS")
                sweeps = t.exporter.sweeps
                await until(lambda: t.exporter.sweeps >= sweeps + 2,
                            "two looks for idle clients while the goal runs")
                assert len(t.exporter.action_clients) == 1, "a busy client was destroyed"
                await ws.send({"op": "cancel_action_goal", "action": topic, "id": "i1"})
                assert (await ws.expect(op="action_result", id="i1", timeout=20))["status"] == 5
                await until(lambda: not t.exporter.action_clients,
                            "the idle action client destroyed")
                await until(lambda: topic not in robot_clients(), "the action client gone from ROS")

                server.slow = False
                await _succeeds(ws, goal, "i2")
            finally:
                await ws.close()
    finally:
        server.destroy()


async def test_a_robots_faulty_goal_replies_end_the_goal_with_a_reason(
        topic: str, caplog: pytest.LogCaptureFixture) -> None:
    """A robot whose goal replies break the wire contract (a plain Zenoh session plays it):
    an ``accepted`` whose id is not hex is dropped with a warning naming it and the goal goes
    on; a result that does
    not fit the action's type ends the goal with the field named, instead of leaving the
    client waiting for ever; the relay serves the next goal."""
    import zenoh

    from bridge_server.zenoh import keys
    from bridge_server.zenoh.keys import GoalEvent, GoalRequest, Snapshot
    from bridge_server.zenoh.link import ZenohOptions, open_session

    fake = "robot2"
    send_goal = topic + "/_action/send_goal"
    snap = Snapshot(node="fake", own_node=("fake", "/"),
                    services=[(send_goal, [FIB + "_SendGoal"])],
                    nodes={"/srv": {"name": "srv", "namespace": "/", "subscribes": [],
                                    "publishes": [], "serves": [[send_goal, [FIB + "_SendGoal"]]]}})

    def answer_graph(query: zenoh.Query) -> None:
        query.reply(query.key_expr, snap.encode())

    def answer_goal(query: zenoh.Query) -> None:
        payload = query.payload.to_bytes() if query.payload is not None else b""
        order = GoalRequest.decode(payload).goal["order"]
        if order == 1:
            events = [GoalEvent("accepted", uuid="not hex"),
                      GoalEvent("result", status=4, values={"sequence": [0, 1]})]
        else:
            events = [GoalEvent("accepted", uuid="00" * 16),
                      GoalEvent("result", status=4, values={"sequence": "none"})]
        for event in events:
            query.reply(query.key_expr, event.encode())

    async with tier() as t:
        session = await open_session(ZenohOptions(connect=[t.router]))
        entities: list[Any] = [
            session.declare_queryable(f"{fake}/{keys.GRAPH}", answer_graph),
            session.declare_queryable(f"{fake}/{keys.GOAL}/**", answer_goal, complete=True),
            session.liveliness().declare_token(f"{fake}/{keys.ALIVE}")]
        try:
            await robot_reachable(t.relay, fake)  # before connecting: 404 until then
            ws = await open_wire(t.url(fake))
            try:
                goal = {"op": "send_action_goal", "action": topic, "action_type": FIB}
                await ws.send({**goal, "args": {"order": 1}, "id": "f1"})
                result = await ws.expect(op="action_result", id="f1", timeout=20)
                assert result["status"] == 4 and result["values"] == {"sequence": [0, 1]}, result
                assert any("uuid that is not hex ('not hex')" in r.getMessage()
                           for r in caplog.records if r.name == "bridge_server.zenoh.graph")

                await ws.send({**goal, "args": {"order": 2}, "id": "f2"})
                result = await ws.expect(op="action_result", id="f2", timeout=20)
                assert result["result"] is False and result["status"] == 6, result
                assert "sequence" in result["values"] and fake in result["values"], result
            finally:
                await ws.close()
        finally:
            for entity in entities:
                entity.undeclare()
            await asyncio.to_thread(session.close)


async def test_a_goal_whose_relay_went_while_it_waited_for_a_server_is_not_sent(
        ros_node: Any, topic: str) -> None:
    """A relay that dies while the robot still waits for the action's server (its
    ``@running`` token goes) takes its goal with it: once the server is there the goal is not
    sent (the query ends canceled), as one canceled while waiting is (a plain Zenoh session
    plays the relay)."""
    from bridge_server.zenoh import keys
    from bridge_server.zenoh.keys import GoalEvent, GoalRequest
    from bridge_server.zenoh.link import ZenohOptions, open_session

    async with tier() as t:
        session = await open_session(ZenohOptions(connect=[t.router]))
        server = None
        try:
            def send(gid: str) -> list[GoalEvent]:
                request = GoalRequest(type=FIB, goal={"order": 3}, feedback=False,
                                      relay="gone", id=gid, timeout=30.0)
                return [GoalEvent.decode(r.ok.payload.to_bytes()) if r.ok else
                        GoalEvent("failed", text=str(r.err.payload.to_string() if r.err else ""))
                        for r in session.get(f"{ROBOT}/{keys.GOAL}/gone{topic}",
                                             payload=request.encode(), timeout=60)]

            token = session.liveliness().declare_token(f"{ROBOT}/{keys.RUNNING}/gone/g1")
            first = asyncio.ensure_future(asyncio.to_thread(send, "g1"))
            second = asyncio.ensure_future(asyncio.to_thread(send, "g2"))
            await until(lambda: ("gone", "g2") in t.exporter._waiting
                        and ("gone", "g1") in t.exporter._waiting,
                        "the robot to wait for the action's server")
            token.undeclare()  # type: ignore[no-untyped-call]
            session.get(f"{ROBOT}/{keys.CANCEL}/gone/g2", lambda _reply: None, timeout=10)
            await until(lambda: {("gone", "g1"), ("gone", "g2")} <= t.exporter._early_cancels,
                        "the robot to hear the relay went and the cancel")
            server = FibServer(ros_node, topic, slow=True)
            for events in (await first, await second):
                assert [(e.event, e.status) for e in events] == [("result", 5)], events
            assert server.goals == []
            assert not t.exporter.goals and not t.exporter._waiting
        finally:
            if server is not None:
                server.destroy()
            await asyncio.to_thread(session.close)


async def test_a_goal_ends_when_the_robot_goes(ros_node: Any, topic: str) -> None:
    """The robot's bridge stops with a relay client's goal in flight: the goal's query ends
    and the client gets a failed result naming the robot, not silence; the restarted robot
    takes the next goal."""
    server = FibServer(ros_node, topic, slow=True)
    try:
        async with tier() as t:
            ws = await open_wire(t.url())
            try:
                goal = await _goal_with_feedback(t, ws, topic, "r1")
                await t.exporter.close()
                await t.robot.close()
                result = await ws.expect(op="action_result", id="r1", timeout=20)
                assert result["result"] is False and ROBOT in result["values"], result
                t.robot, t.exporter = await start_robot(t.router)
                await until(server.cancel_requests.is_set,
                            "the stopped robot's goal canceled on the server")
                server.slow = False
                await _relay_lists(t, topic)
                await _succeeds(ws, goal, "r2")
            finally:
                await ws.close()
    finally:
        server.destroy()
