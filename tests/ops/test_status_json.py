"""/status.json: what the status page is drawn from, and how workers' snapshots merge."""

from __future__ import annotations

from typing import Any

from bridge_server.http.metrics import LATENCY_BUCKETS
from bridge_server.http.snapshot import merge
from tests.bridge.action_support import FIB, FibServer, bridge_sees_action, send_goal
from tests.helpers import BridgeProcess, open_wire
from tests.ops.support import status


async def test_status_lists_clients_services_and_actions(make_bridge: Any, topic: str) -> None:
    """A client's address, subscriptions, publishers, served service and served action appear."""
    b: BridgeProcess = make_bridge()
    ws = await open_wire(b.url)
    try:
        await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String",
                       "queue_length": 7})
        await ws.send({"op": "advertise", "topic": topic + "_out", "type": "std_msgs/msg/String"})
        await ws.send({"op": "advertise_service", "service": topic + "_srv",
                       "type": "std_srvs/srv/Trigger"})
        await ws.send({"op": "advertise_action", "action": topic + "_act",
                       "type": "test_msgs/action/Fibonacci"})
        await ws.send({"op": "call_service", "service": "/rosapi/topics", "id": "sync"})
        await ws.expect(op="service_response", id="sync")
        s = await status(b.port)
    finally:
        await ws.close()
    assert s["version"] == "0.1.0" and s["now"] >= s["started"]
    (client,) = s["clients"]
    assert client["id"] == "0-1" and client["address"].startswith("127.0.0.1:")
    assert client["subscriptions"] == [{"topic": topic, "type": "std_msgs/msg/String",
                                        "queued": 0, "queue_length": 7, "dropped": 0,
                                        "sent": 0}]
    assert client["publishes"] == [topic + "_out"]
    assert client["serves"] == [topic + "_srv"]
    assert s["services"] == [{"name": topic + "_srv", "type": "std_srvs/srv/Trigger",
                              "served_by": "0-1"}]
    assert s["actions"] == [{"name": topic + "_act", "type": "test_msgs/action/Fibonacci",
                             "served_by": "0-1", "goals": 0}]
    assert s["topics"][topic]["subscribers"] == 1


async def test_status_names_the_type_of_an_action_served_in_ros(
    make_bridge: Any, ros_node: Any, topic: str
) -> None:
    """An rclpy action server's type is listed once goals to it are counted, when no goal is
    in flight: after a goal of the wrong type (which made no action client), and after the
    server went away (the bridge's action client keeps the name in the graph)."""
    b: BridgeProcess = make_bridge()
    action = topic + "_act"
    fib = FibServer(ros_node, action)
    server: FibServer | None = fib  # None once destroyed
    ws = await open_wire(b.url)
    try:
        await bridge_sees_action(ws, action)
        await ws.send({"op": "send_action_goal", "action": action, "id": "wrong",
                       "action_type": "test_msgs/action/NestedMessage", "args": {}})
        result = await ws.expect(op="action_result", id="wrong", timeout=20)
        assert result["status"] == 6 and f"has type {FIB}" in result["values"], result
        s = await status(b.port)
        assert s["actions"] == [{"name": action, "type": FIB, "served_by": "ROS", "goals": 0}]

        await send_goal(ws, action, {"order": 2}, "right")
        assert (await ws.expect(op="action_result", id="right", timeout=20))["status"] == 4
        fib.destroy()
        server = None
        await bridge_sees_action(ws, action, gone=True)
        s = await status(b.port)
        assert s["actions"] == [{"name": action, "type": FIB, "served_by": "ROS", "goals": 0}]
        assert s["action_goals"][action]["outcomes"] == {"failed": 1, "succeeded": 1}
    finally:
        await ws.close()
        if server is not None:
            server.destroy()


def _snap(worker: int, sent: int, rate: float, clients: int) -> dict[str, Any]:
    buckets = [0] * (len(LATENCY_BUCKETS) + 1)
    buckets[3] = sent
    return {
        "version": "0.1.0", "worker": worker, "started": 100.0 + worker, "connections": clients,
        "workers": [{"index": worker}], "refused": {"auth": 1}, "errors": {"protocol": worker},
        "service_calls": {"/s": {"outcomes": {"ok": sent}, "buckets": buckets, "sum": 0.5}},
        "action_goals": {},
        "topics": {"/t": {"type": "std_msgs/msg/String", "sent": sent,
                          "ros_received_per_s": rate, "sent_per_s": rate * clients}},
        "clients": [{"worker": worker, "sid": i} for i in range(clients)],
        "services": [], "actions": [],
    }


def test_merge_adds_counts_joins_lists_and_takes_the_max_ros_rate() -> None:
    """Merging two workers: counters and histograms add up; each worker's ROS rate is the same
    stream, so the topic's rate from ROS is the max, while rates to clients add up."""
    m = merge([_snap(0, 10, 50.0, 2), _snap(1, 5, 49.0, 1)])
    assert m["connections"] == 3 and m["started"] == 100.0
    assert [w["index"] for w in m["workers"]] == [0, 1]
    assert [(c["worker"], c["sid"]) for c in m["clients"]] == [(0, 0), (0, 1), (1, 0)]
    assert m["refused"] == {"auth": 2} and m["errors"] == {"protocol": 1}
    calls = m["service_calls"]["/s"]
    assert calls["outcomes"] == {"ok": 15} and calls["buckets"][3] == 15 and calls["sum"] == 1.0
    t = m["topics"]["/t"]
    assert (t["type"], t["sent"], t["ros_received_per_s"], t["sent_per_s"]) == (
        "std_msgs/msg/String", 15, 50.0, 149.0)


def test_merge_lists_each_action_once() -> None:
    """Workers that both use an action: one row, goals in flight added up, the type one of
    them knows, and the client that serves it rather than ROS."""
    a, b, c = _snap(0, 1, 1.0, 1), _snap(1, 1, 1.0, 1), _snap(2, 1, 1.0, 1)
    a["actions"] = [{"name": "/a", "type": None, "served_by": "ROS", "goals": 1},
                    {"name": "/z", "type": FIB, "served_by": "ROS", "goals": 0}]
    b["actions"] = [{"name": "/a", "type": FIB, "served_by": "ROS", "goals": 2}]
    c["actions"] = [{"name": "/a", "type": FIB, "served_by": "2-1", "goals": 0},
                    {"name": "/b", "type": FIB, "served_by": "ROS", "goals": 0}]
    assert merge([a, b, c])["actions"] == [
        {"name": "/a", "type": FIB, "served_by": "2-1", "goals": 3},
        {"name": "/b", "type": FIB, "served_by": "ROS", "goals": 0},
        {"name": "/z", "type": FIB, "served_by": "ROS", "goals": 0},
    ]
    assert a["actions"][0]["goals"] == 1  # the workers' snapshots are left as they were
