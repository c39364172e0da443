"""The relay's status page and /metrics (issue 26): its robots, and each robot's bridge page.

Real HTTP against a real tier (tests/relay/support.py): the relay as Zenoh router, robots'
rclpy bridges dialing out, websocket clients subscribing and publishing through it.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

import pytest
from std_msgs.msg import String
from websockets.exceptions import InvalidStatus

from bridge_server.zenoh.relay import Relay
from rosbridge_core.security.auth import new_token
from tests.helpers import CHROMEDRIVER, CHROMIUM, WireClient, headless_chromium, open_wire
from tests.ops.support import aget
from tests.relay.support import (
    ROBOT,
    ROBOT1_VIEWER,
    Tier,
    relay_serving,
    relay_with_auth,
    tier,
    until,
)

pytestmark = pytest.mark.timeout(120)


async def _json(url: str) -> Any:
    code, _, body = await aget(url)
    assert code == 200, (url, code, body)
    return json.loads(body)


async def _metrics(url: str) -> dict[tuple[str, frozenset[tuple[str, str]]], float]:
    """``/metrics`` parsed: (sample name, labels) -> value."""
    from prometheus_client.parser import text_string_to_metric_families

    code, headers, body = await aget(url)
    assert code == 200, (url, code, body)
    assert headers["content-type"].startswith("text/plain")
    return {(s.name, frozenset(s.labels.items())): s.value
            for f in text_string_to_metric_families(body.decode()) for s in f.samples}


def _robot(status: dict[str, Any], name: str) -> dict[str, Any]:
    found: list[dict[str, Any]] = [r for r in status["robots"] if r["name"] == name]
    assert found, f"robot {name} not listed: {status['robots']}"
    return found[0]


@contextlib.asynccontextmanager
async def _watching(pub: Any, topic: str, data: str) -> AsyncIterator[tuple[Tier, WireClient]]:
    """A tier and a client of the relay subscribed to the robot's ``topic``, once it heard
    a message: ``data`` is published on the robot (``pub``) until then (discovery has no
    event), then one ``fence`` message behind any still on their way."""
    async with tier() as t:
        ws = await open_wire(t.url())
        try:
            await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String"})
            deadline = asyncio.get_running_loop().time() + 20
            while True:
                pub.publish(String(data=data))
                try:
                    await ws.expect(op="publish", topic=topic, timeout=0.3)
                    break
                except AssertionError:
                    assert asyncio.get_running_loop().time() < deadline, "never heard the robot"
            # A fence: the messages above still in flight come before it (one ordered
            # stream), so nothing more comes after it unless the test publishes.
            pub.publish(String(data="fence"))
            await ws.expect(_carrying("fence"), op="publish")
            yield t, ws
        finally:
            await ws.close()


def _carrying(data: str) -> Callable[[Any], bool]:
    """A ``publish`` op's predicate: its message is ``{"data": data}``."""
    return lambda op: bool(op.get("msg") == {"data": data})


async def test_relay_status_and_metrics_per_robot_and_client(ros_node: Any, topic: str) -> None:
    """/status.json lists the robot (present, clients, topics watched, messages and bytes each
    way), /robot1/status.json is the bridge's snapshot with the client and its subscription,
    /metrics carries every series with robot="robot1" and its presence; when the robot goes
    away it shows as not present."""
    pub = ros_node.create_publisher(String, topic, 10)
    async with _watching(pub, topic, "x" * 100) as (t, ws):
        base = f"http://127.0.0.1:{t.relay.port}"
        back = topic + "_back"
        await ws.send({"op": "advertise", "topic": back, "type": "std_msgs/msg/String"})
        for _ in range(3):
            await ws.send({"op": "publish", "topic": back, "msg": {"data": "hi"}})
        await ws.send({"op": "call_service", "service": "/rosapi/topics", "id": "sync"})
        await ws.expect(op="service_response", id="sync")

        status = await _json(base + "/status.json")
        assert status["relay"] == t.relay.relay_id and status["ready"] is True
        robot = _robot(status, ROBOT)
        assert robot["present"] is True and robot["served"] is True
        assert robot["clients"] == 1 and robot["clients_by_protocol"] == {"rosbridge": 1}
        assert robot["topics_watched"] == [topic]
        assert robot["messages_from_robot"] >= 1
        assert robot["messages_to_clients"] >= 1 and robot["bytes_to_clients"] > 100
        assert robot["messages_from_clients"] == 3 and robot["bytes_from_clients"] > 0

        own = await _json(f"{base}/{ROBOT}/status.json")
        (client,) = own["clients"]
        assert client["address"].startswith("127.0.0.1:")
        assert [s["topic"] for s in client["subscriptions"]] == [topic]
        assert client["publishes"] == [back]
        assert own["topics"][topic]["subscribers"] == 1

        m = await _metrics(base + "/metrics")
        on = frozenset({("robot", ROBOT)})
        assert m[("roslibpy_relay_robot_present", on)] == 1
        assert m[("roslibpy_bridge_clients", on)] == 1
        assert m[("roslibpy_bridge_messages_total", on | {("topic", topic),
                                                          ("direction", "ros_to_client")})] >= 1
        assert m[("roslibpy_bridge_messages_total", on | {("topic", back),
                                                          ("direction", "client_to_ros")})] == 3
        assert m[("roslibpy_bridge_bytes_total", on | {("topic", topic),
                                                       ("direction", "ros_to_client")})] > 100
        own_metrics = await _metrics(f"{base}/{ROBOT}/metrics")  # the bridge's, unlabelled
        assert own_metrics[("roslibpy_bridge_clients", frozenset())] == 1

        code, _, _ = await aget(f"{base}/{ROBOT}")
        assert code == 200  # redirected to /robot1/: the bridge's page
        code, _, page = await aget(f"{base}/{ROBOT}/")
        assert code == 200 and b"roslibpy-lite bridge" in page
        code, _, page = await aget(base + "/")
        assert code == 200 and b"roslibpy-lite relay" in page
        assert (await aget(base + "/readyz"))[0] == 200
        assert (await aget(f"{base}/{ROBOT}/readyz"))[0] == 200
        code, _, body = await aget(f"{base}/robot2/status.json")
        assert code == 404 and b"no robot named 'robot2'" in body
        with pytest.raises(InvalidStatus):  # a websocket for a robot that is not there
            await open_wire(t.url("robot2"))
        assert (await _json(base + "/status.json"))["refused"] == {"unknown_robot": 1}
        m = await _metrics(base + "/metrics")
        assert m[("roslibpy_relay_connections_refused_total",
                  frozenset({("reason", "unknown_robot")}))] == 1

        await t.exporter.close()  # the robot leaves the network
        await until(lambda: t.relay.robots[ROBOT].web.ready() is not None,
                    "the relay to see the robot go")
        robot = _robot(await _json(base + "/status.json"), ROBOT)
        assert robot["present"] is False and robot["clients"] == 1
        m = await _metrics(base + "/metrics")
        assert m[("roslibpy_relay_robot_present", on)] == 0
        code, _, body = await aget(f"{base}/{ROBOT}/readyz")
        assert code == 503 and b"robot1 is not connected" in body


async def test_relay_counts_bytes_from_each_robot(ros_node: Any, topic: str) -> None:
    """Bytes from the robot: each message of a known size the robot publishes to a watched
    topic adds exactly its CDR payload to the robot's ``bytes_from_robot`` on /status.json
    and to ``roslibpy_relay_bytes_from_robot_total{robot}`` on /metrics."""
    from rclpy.serialization import serialize_message

    pub = ros_node.create_publisher(String, topic, 100)
    async with _watching(pub, topic, "sync") as (t, ws):
        base = f"http://127.0.0.1:{t.relay.port}"

        def figures(status: dict[str, Any], m: dict[Any, float]) -> tuple[int, float]:
            return (_robot(status, ROBOT)["bytes_from_robot"],
                    m[("roslibpy_relay_bytes_from_robot_total",
                       frozenset({("robot", ROBOT)}))])

        before = figures(await _json(base + "/status.json"), await _metrics(base + "/metrics"))
        assert before[0] > 0 and before[0] == before[1]
        count, sizes = 10, 0
        for i in range(count):  # one at a time: none can be lost to a full queue
            msg = String(data=f"{i:04d}" + "y" * 996)
            sizes += len(serialize_message(msg))
            pub.publish(msg)
            await ws.expect(_carrying(msg.data), op="publish")
        assert sizes > count * 1000
        after = figures(await _json(base + "/status.json"), await _metrics(base + "/metrics"))
        assert after == (before[0] + sizes, before[1] + sizes), (before, after, sizes)


async def test_robots_named_like_the_relays_routes_have_their_pages() -> None:
    """Robots named ``metrics`` and ``static`` (the relay's own routes): each one's page,
    snapshot and metrics are under /robots/<name>/ (the relay's page links there), its
    websocket at /<name> serves it, and /metrics and /static/ stay the relay's."""
    names = ("metrics", "static")
    async with relay_serving(names) as relay:
        base = f"http://127.0.0.1:{relay.port}"
        for name in names:
            for path in (f"/robots/{name}/", f"/robots/{name}"):  # redirected to the first
                code, _, page = await aget(base + path)
                assert code == 200 and b"roslibpy-lite bridge" in page, (path, code, page)
            own = await _json(f"{base}/robots/{name}/status.json")
            assert own["clients"] == [] and "topics" in own, own
            own_metrics = await _metrics(f"{base}/robots/{name}/metrics")
            assert own_metrics[("roslibpy_bridge_clients", frozenset())] == 0
            assert (await aget(f"{base}/robots/{name}/readyz"))[0] == 200
            ws = await open_wire(f"ws://127.0.0.1:{relay.port}/{name}")
            try:
                await ws.send({"op": "call_service", "service": "/rosapi/nodes", "id": "n"})
                reply = await ws.expect(op="service_response", id="n")
                assert reply["result"] is True, reply
                assert (await _json(f"{base}/robots/{name}/status.json"))["clients"]
            finally:
                await ws.close()
        m = await _metrics(base + "/metrics")  # still the relay's, with both robots
        assert {dict(labels).get("robot") for name, labels in m
                if name == "roslibpy_relay_robot_present"} == set(names)
        code, _, js = await aget(base + "/static/relay.js")  # still the relay's file
        assert code == 200 and b'"/robots/" + encodeURIComponent' in js
        assert [r["name"] for r in (await _json(base + "/status.json"))["robots"]] == sorted(
            names)
        code, _, body = await aget(f"{base}/robots/robot2/status.json")
        assert code == 404 and b"no robot named 'robot2'" in body
        code, _, page = await aget(f"{base}/robots/")  # redirected to the relay's page
        assert code == 200 and b"roslibpy-lite relay" in page


ROLES = ROBOT1_VIEWER + """
[roles.fleet_viewer]
subscribe = ["*"]
introspection = ["*"]

[roles.driver]
subscribe = ["*"]
"""


@pytest.fixture
async def relay_with_roles(tmp_path: Path) -> AsyncIterator[tuple[Relay, dict[str, str]]]:
    """A relay with the roles above (a token each) serving robot1 and robot2."""
    async with relay_with_auth(tmp_path / "auth.toml", ROLES) as served:
        yield served


async def test_relay_pages_follow_tokens_roles_and_robots(
        relay_with_roles: tuple[Relay, dict[str, str]]) -> None:
    """With an auth file: no token or a wrong one is 401 (the token never in the answer), a
    role without introspection 403; a role limited to robot1 sees robot1 alone in the lists
    and metrics and is refused robot2's page; a fleet role sees both."""
    relay, tokens = relay_with_roles
    base = f"http://127.0.0.1:{relay.port}"
    for path in ("/status.json", "/metrics", f"/{ROBOT}/status.json", f"/{ROBOT}/metrics"):
        code, _, body = await aget(base + path)
        assert code == 401 and b"authentication required" in body, (path, code, body)
        wrong = new_token()
        code, _, body = await aget(f"{base}{path}?token={wrong}")
        assert code == 401 and wrong.encode() not in body, (path, code, body)
        code, _, body = await aget(f"{base}{path}?token={tokens['driver']}")
        assert code == 403, (path, code, body)
    for path in ("/", "/static/relay.js", "/healthz", "/readyz"):  # no data: open
        assert (await aget(base + path))[0] == 200, path

    fleet = f"?token={tokens['fleet_viewer']}"
    for name in ("robot1", "robot2"):  # each robot's page (the relay serves both now)
        assert (await aget(f"{base}/{name}/status.json{fleet}"))[0] == 200
    status = await _json(base + "/status.json" + fleet)
    assert [(r["name"], r["present"], r["served"]) for r in status["robots"]] == [
        ("robot1", True, True), ("robot2", True, True)]
    m = await _metrics(base + "/metrics" + fleet)
    assert {dict(labels).get("robot") for _, labels in m} == {"robot1", "robot2"}

    one = f"?token={tokens['robot1_viewer']}"
    status = await _json(base + "/status.json" + one)
    assert [r["name"] for r in status["robots"]] == ["robot1"]
    m = await _metrics(base + "/metrics" + one)
    assert {dict(labels).get("robot") for _, labels in m} == {"robot1"}
    assert (await aget(f"{base}/robot1/status.json{one}"))[0] == 200
    code, _, body = await aget(f"{base}/robot2/status.json{one}")
    assert code == 403 and b"may not see it" in body, body


@pytest.mark.skipif(CHROMIUM is None or CHROMEDRIVER is None,
                    reason="chromium and chromium-driver are not installed (scripts/setup.sh)")
async def test_relay_page_in_a_browser(ros_node: Any, topic: str) -> None:
    """Headless Chromium: the relay's page lists robot1 with its client, watched topic and
    the bytes it received from the robot; its link opens the bridge's page for robot1, which
    shows the client."""
    pub = ros_node.create_publisher(String, topic, 10)
    async with _watching(pub, topic, "seen") as (t, _):
        # Past the fence nothing more comes from the robot: the count is final, the same
        # before and after the page is read, and the page shows it.
        status = f"http://127.0.0.1:{t.relay.port}/status.json"
        received = _robot(await _json(status), ROBOT)["bytes_from_robot"]
        assert received > 0
        seen = await asyncio.to_thread(_browse, f"http://127.0.0.1:{t.relay.port}/", topic)
        assert _robot(await _json(status), ROBOT)["bytes_from_robot"] == received
    assert seen["robot"][:4] == [ROBOT, "yes", "1", topic], seen
    assert seen["bytes_from_robot"] == str(received), seen
    assert seen["clients"] == "1" and topic in seen["client_row"], seen
    assert seen["robot_url"].endswith(f"/robots/{ROBOT}/"), seen


def _browse(url: str, topic: str) -> dict[str, Any]:
    """The relay page's robot1 row, then (following its link) the robot page's client row."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    with headless_chromium("relay-status") as driver:
        driver.get(url)
        row = ("return Array.from(document.querySelectorAll('#robots tr[data-robot]'))"
               ".map((tr) => Array.from(tr.cells).map((td) => td.innerText.trim()))[0] || null")
        robot = WebDriverWait(driver, 30, poll_frequency=0.1).until(
            lambda d: (r := d.execute_script(row)) and topic in r and r)
        received = driver.execute_script(  # the exact count behind the shown "1.2 KB"
            "return document.querySelector('#robots tr[data-robot] td:nth-child(5) .traffic')"
            ".dataset.bytes")
        driver.find_element(By.LINK_TEXT, ROBOT).click()
        client = ("const r = document.querySelector('#clients tbody tr');"
                  "return [document.getElementById('client-count').innerText,"
                  " r ? r.innerText : '']")
        count, client_row = WebDriverWait(driver, 30, poll_frequency=0.1).until(
            lambda d: (c := d.execute_script(client)) and topic in c[1] and c)
        return {"robot": robot, "bytes_from_robot": received, "clients": count, "client_row": client_row,
                "robot_url": driver.current_url}
