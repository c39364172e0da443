"""--workers 2: two bridge processes on one port, talking through DDS like any two nodes."""

from __future__ import annotations

import json
import os
import signal
import time
from collections.abc import Iterator

import psutil
import pytest

from tests.helpers import BridgeProcess, WireClient, async_wait_until, open_wire, wait_until
from tests.ops.support import http_get, scrape, status, value


@pytest.fixture(scope="module")
def workers() -> Iterator[BridgeProcess]:
    """One bridge with two workers for this module."""
    proc = BridgeProcess(args=["--workers", "2", "--metrics-port", "0"]).start()
    yield proc
    proc.stop()


async def connect_on(bridge: BridgeProcess, worker: int, tries: int = 60) -> WireClient:
    """A client that the kernel handed to ``worker`` (others opened on the way are closed)."""
    for _ in range(tries):
        ws = await open_wire(bridge.url)
        assert ws.ws.response is not None
        if ws.ws.response.headers["X-Bridge-Worker"] == str(worker):
            return ws
        await ws.close()
    raise AssertionError(f"no connection landed on worker {worker} in {tries} tries")


async def test_both_workers_take_clients_and_the_view_covers_both(
    workers: BridgeProcess, topic: str
) -> None:
    """Clients land on both workers; /status.json and /metrics show the whole bridge."""
    a, b = await connect_on(workers, 0), await connect_on(workers, 1)
    try:
        await a.send({"op": "subscribe", "topic": topic + "_a", "type": "std_msgs/msg/String"})
        await b.send({"op": "subscribe", "topic": topic + "_b", "type": "std_msgs/msg/String"})
        for ws in (a, b):
            await ws.send({"op": "call_service", "service": "/rosapi/topics", "id": "sync"})
            await ws.expect(op="service_response", id="sync")
        s = await status(workers.port)
        assert [w["index"] for w in s["workers"]] == [0, 1]
        assert len({w["node"] for w in s["workers"]}) == 2
        mine = {c["worker"]: c for c in s["clients"]
                if any(sub["topic"].startswith(topic) for sub in c["subscriptions"])}
        assert set(mine) == {0, 1}
        assert {topic + "_a", topic + "_b"} <= set(s["topics"])
        line = workers.wait_for_line(r"metrics on http://127\.0\.0\.1:\d+/metrics")
        metrics_port = int(line.rsplit(":", 1)[1].split("/")[0])
        for port in (workers.port, metrics_port):  # the bridge's port, and --metrics-port
            m = await scrape(port)
            assert value(m, "roslibpy_bridge_workers") == 2
            assert value(m, "roslibpy_bridge_topic_subscribers", topic=topic + "_a") == 1
            assert value(m, "roslibpy_bridge_topic_subscribers", topic=topic + "_b") == 1
    finally:
        await a.close()
        await b.close()


async def test_publisher_on_one_worker_reaches_a_subscriber_on_the_other(
    workers: BridgeProcess, topic: str
) -> None:
    """A client publishing through worker 0 is heard by a client subscribed through worker 1."""
    pub, sub = await connect_on(workers, 0), await connect_on(workers, 1)
    try:
        await sub.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String"})
        await pub.send({"op": "advertise", "topic": topic, "type": "std_msgs/msg/String"})
        got = None
        for i in range(100):  # until discovery has matched the two nodes
            await pub.send({"op": "publish", "topic": topic, "msg": {"data": f"n{i}"}})
            try:
                got = await sub.expect(op="publish", topic=topic, timeout=0.2)
                break
            except AssertionError:
                continue
        assert got is not None and got["msg"]["data"].startswith("n")
    finally:
        await pub.close()
        await sub.close()


async def test_latched_topic_reaches_a_late_subscriber_on_the_other_worker(
    workers: BridgeProcess, topic: str
) -> None:
    """A latched message published through worker 0 reaches a later subscriber on worker 1."""
    pub = await connect_on(workers, 0)
    try:
        await pub.send({"op": "advertise", "topic": topic, "type": "std_msgs/msg/String",
                        "latch": True})
        await pub.send({"op": "publish", "topic": topic, "msg": {"data": "latched"}})
        await pub.send({"op": "call_service", "service": "/rosapi/topics", "id": "sync"})
        await pub.expect(op="service_response", id="sync")
        sub = await connect_on(workers, 1)
        try:
            await sub.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String"})
            got = await sub.expect(op="publish", topic=topic, timeout=15)
            assert got["msg"] == {"data": "latched"}
        finally:
            await sub.close()
    finally:
        await pub.close()


async def test_service_served_on_one_worker_called_from_the_other(
    workers: BridgeProcess, topic: str
) -> None:
    """A service a client serves through worker 0 answers a client calling through worker 1."""
    server, caller = await connect_on(workers, 0), await connect_on(workers, 1)
    try:
        await server.send({"op": "advertise_service", "service": topic,
                           "type": "std_srvs/srv/SetBool"})
        await server.send({"op": "call_service", "service": "/rosapi/topics", "id": "sync"})
        await server.expect(op="service_response", id="sync")
        await caller.send({"op": "call_service", "service": topic, "type": "std_srvs/srv/SetBool",
                           "args": {"data": True}, "id": "c1", "timeout": 15})
        request = await server.expect(op="call_service", service=topic, timeout=15)
        assert request["args"] == {"data": True}
        await server.send({"op": "service_response", "service": topic, "id": request["id"],
                           "result": True, "values": {"success": True, "message": "from w0"}})
        reply = await caller.expect(op="service_response", id="c1", timeout=15)
        assert reply["result"] is True
        assert reply["values"] == {"success": True, "message": "from w0"}
    finally:
        await server.close()
        await caller.close()


async def test_a_dead_worker_is_restarted(workers: BridgeProcess) -> None:
    """Killing a worker: the supervisor starts a new one with the same index."""
    before = {w["index"]: w["pid"] for w in (await status(workers.port))["workers"]}
    os.kill(before[1], signal.SIGKILL)

    def replaced() -> bool:
        try:  # a connection the kernel gave the dying worker is reset
            code, _, body = http_get(f"http://127.0.0.1:{workers.port}/status.json")
        except OSError:
            return False
        if code != 200:
            return False
        now = {w["index"]: w["pid"] for w in json.loads(body)["workers"]}
        return now.get(1) not in (None, before[1]) and now.get(0) == before[0]

    await async_wait_until(replaced, 30, "worker 1 to be restarted")
    workers.wait_for_line(r"worker 1 .*exited .*restarting")


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_stops_every_worker(sig: int) -> None:
    """SIGTERM or SIGINT to the supervisor stops it and all its workers (about a second)."""
    proc = BridgeProcess(args=["--workers", "2"]).start()
    assert proc.proc is not None
    children = [c.pid for c in psutil.Process(proc.proc.pid).children()]
    assert len(children) == 2
    t0 = time.monotonic()
    assert proc.stop(sig) == 0
    print(f"stopped in {time.monotonic() - t0:.2f} s")
    wait_until(lambda: not any(psutil.pid_exists(p) and psutil.Process(p).status()
                               != psutil.STATUS_ZOMBIE for p in children), 5, "workers gone")




def test_workers_stop_when_the_supervisor_is_killed() -> None:
    """SIGKILL to the supervisor (no chance to stop anyone): its workers notice and exit."""
    proc = BridgeProcess(args=["--workers", "2"]).start()
    assert proc.proc is not None
    children = psutil.Process(proc.proc.pid).children()
    assert len(children) == 2
    proc.kill()
    _, alive = psutil.wait_procs(children, timeout=10)
    assert not alive, f"workers still running after their supervisor was killed: {alive}"
