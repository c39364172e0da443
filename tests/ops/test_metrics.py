"""/metrics: real clients and rclpy peers, scraped and parsed with prometheus_client's parser."""

from __future__ import annotations

from typing import Any

from bridge_server.http.metrics import LABEL_LIMIT, OTHER, LabelCap
from tests.bridge.support import wait_subscribers
from tests.helpers import BridgeProcess, open_wire
from tests.ops.support import aget, scrape, value

P = "roslibpy_bridge_"


def test_label_cap_folds_new_values_past_the_limit() -> None:
    """A LabelCap admits the first N distinct values and folds every later one into "other"."""
    cap = LabelCap(3)
    assert [cap(v) for v in ("a", "b", "a", "c", "d", "b", "e")] == ["a", "b", "a", "c", OTHER,
                                                                     "b", OTHER]


async def test_topic_traffic_calls_and_errors_are_counted(
    make_bridge: Any, ros_node: Any, topic: str
) -> None:
    """Messages and bytes both ways, service calls with outcomes and latency, errors by kind."""
    from std_msgs.msg import String

    b: BridgeProcess = make_bridge()
    ws = await open_wire(b.url)
    try:
        await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String"})
        pub = ros_node.create_publisher(String, topic, 10)
        await wait_subscribers(pub)
        for i in range(5):
            pub.publish(String(data=f"m{i}"))
            await ws.expect(op="publish", topic=topic)
        back = topic + "_back"
        await ws.send({"op": "advertise", "topic": back, "type": "std_msgs/msg/String"})
        for _ in range(3):
            await ws.send({"op": "publish", "topic": back, "msg": {"data": "x"}})
        await ws.send({"op": "call_service", "service": "/rosapi/topics", "id": "ok"})
        await ws.expect(op="service_response", id="ok", result=True)
        await ws.send({"op": "call_service", "service": topic + "_nosrv", "id": "gone",
                       "type": "std_srvs/srv/Trigger", "timeout": 0.3})
        await ws.expect(op="service_response", id="gone", result=False)
        await ws.send_raw("{not json")
        await ws.expect(op="status", level="error")

        m = await scrape(b.port)
        assert value(m, P + "clients") == 1
        assert value(m, P + "connections_total") == 1
        assert value(m, P + "topic_subscribers", topic=topic) == 1
        assert value(m, P + "ros_messages_received_total", topic=topic) == 5
        assert value(m, P + "messages_total", topic=topic, direction="ros_to_client") == 5
        assert value(m, P + "bytes_total", topic=topic, direction="ros_to_client") > 5 * 30
        assert value(m, P + "messages_total", topic=back, direction="client_to_ros") == 3
        assert value(m, P + "bytes_total", topic=back, direction="client_to_ros") > 3 * 30
        assert value(m, P + "service_calls_total", service="/rosapi/topics", outcome="ok") == 1
        assert value(m, P + "service_calls_total", service=topic + "_nosrv",
                     outcome="unavailable") == 1
        assert value(m, P + "service_call_duration_seconds_count", service="/rosapi/topics") == 1
        assert value(m, P + "service_call_duration_seconds_bucket", service="/rosapi/topics",
                     le="+Inf") == 1
        assert value(m, P + "errors_total", kind="protocol") == 1
    finally:
        await ws.close()
    # Once the client is gone its counts stay (counters never go down).
    m = await scrape(b.port)
    assert value(m, P + "messages_total", topic=topic, direction="ros_to_client") == 5
    assert value(m, P + "connections_total") == 1


async def test_a_flood_of_topic_names_keeps_labels_bounded(make_bridge: Any, topic: str) -> None:
    """Subscribing to more topic names than the cap folds the rest into "other"."""
    b: BridgeProcess = make_bridge()
    ws = await open_wire(b.url)
    try:
        n = LABEL_LIMIT + 60
        for i in range(n):
            await ws.send({"op": "subscribe", "topic": f"{topic}/flood{i}"})
        await ws.send({"op": "call_service", "service": "/rosapi/topics", "id": "sync"})
        await ws.expect(op="service_response", id="sync")
        m = await scrape(b.port)
        labels = {lab["topic"] for lab, _ in m[P + "topic_subscribers"]}
        assert len(labels) == LABEL_LIMIT + 1
        assert OTHER in labels
        assert sum(v for _, v in m[P + "topic_subscribers"]) == n
    finally:
        await ws.close()


async def test_metrics_port_serves_the_same_metrics(make_bridge: Any) -> None:
    """--metrics-port answers /metrics (and /healthz) on a port of its own."""
    b: BridgeProcess = make_bridge("--metrics-port", "0")
    line = b.wait_for_line(r"metrics on http://127\.0\.0\.1:(\d+)/metrics")
    port = int(line.rsplit(":", 1)[1].split("/")[0])
    ws = await open_wire(b.url)
    try:
        m = await scrape(port)
        assert value(m, P + "clients") == 1
        code, _, body = await aget(f"http://127.0.0.1:{port}/healthz")
        assert (code, body) == (200, b"ok\n")
    finally:
        await ws.close()


async def test_refused_connections_are_counted_by_reason(make_bridge: Any) -> None:
    """A handshake the security checks refuse (a foreign Origin) counts as refused, reason origin."""
    from websockets.asyncio.client import connect
    from websockets.exceptions import InvalidStatus

    b: BridgeProcess = make_bridge("--allowed-origins", "http://robot.example")
    try:
        async with connect(b.url, origin="http://elsewhere.example"):  # type: ignore[arg-type]
            raise AssertionError("the handshake should have been refused")
    except InvalidStatus as exc:
        assert exc.response.status_code == 403
    m = await scrape(b.port)
    assert value(m, P + "connections_refused_total", reason="origin") == 1
    assert value(m, P + "connections_total") == 0


async def test_queue_drops_are_counted_per_client_and_topic(
    make_bridge: Any, ros_node: Any, topic: str
) -> None:
    """A client that stops reading drops messages: counted per topic and per client, and shown
    on the status data; a reading client on the same topic drops nothing."""
    import asyncio

    from std_msgs.msg import String

    from tests.load.support import StalledClient, qos
    from tests.ops.support import status

    b: BridgeProcess = make_bridge()
    total, pad = 60, "x" * 200_000  # 12 MB: far beyond the socket buffers
    stalled = await asyncio.to_thread(StalledClient, b.port)
    witness = await open_wire(b.url)
    try:
        stalled.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String",
                      "queue_length": 2})
        await asyncio.to_thread(stalled.sync)  # subscribed; from now on it never reads
        await witness.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String",
                            "queue_length": total})
        await witness.send({"op": "call_service", "service": "/rosapi/topics", "id": "sync"})
        await witness.expect(op="service_response", id="sync")
        pub = ros_node.create_publisher(String, topic, qos(depth=total))
        await wait_subscribers(pub)
        for i in range(total):
            pub.publish(String(data=f"{i}:{pad}"))
        await witness.expect(lambda op: op["msg"]["data"].startswith(f"{total - 1}:"),
                             op="publish", timeout=20)
        m = await scrape(b.port)
        s = await status(b.port)
    finally:
        stalled.close()
        await witness.close()
    dropped = value(m, P + "queue_drops_total", topic=topic)
    assert dropped > 0
    assert value(m, P + "client_queue_drops_total", client="0-1", topic=topic) == dropped
    assert value(m, P + "client_queue_drops_total", client="0-2", topic=topic) == 0
    # its queue of 2, plus the drop warning that waits for it too (the kernel holds only
    # --notsent-lowat unsent bytes, so little that the stalled client never got even that)
    assert value(m, P + "client_queued_messages", client="0-1") <= 2 + 1
    by_id = {c["id"]: c for c in s["clients"]}
    assert by_id["0-1"]["dropped"] == dropped and by_id["0-2"]["dropped"] == 0
    assert s["topics"][topic]["drops"] == dropped
