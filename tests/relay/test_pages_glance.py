"""The relay's page and a robot's pages as a person sees them at 1280 px, in headless
Chromium (issue 50, item 3): units, separators and rates beside the counters, a robots table
that does not scroll sideways, the robot's name in every robot page's title, and the relay's
process apart from the robot's nodes."""

from __future__ import annotations

import asyncio
import re
from typing import Any

import pytest
from std_msgs.msg import String

from tests.helpers import CHROMEDRIVER, CHROMIUM, headless_chromium, open_wire
from tests.http.pageshot import OVERFLOW, shot
from tests.ops.support import aget
from tests.relay.support import ROBOT, tier

pytestmark = [pytest.mark.timeout(150), pytest.mark.skipif(
    CHROMIUM is None or CHROMEDRIVER is None,
    reason="chromium and chromium-driver are not installed (scripts/setup.sh installs them)")]

_ROW = """
const tr = document.querySelector('#robots tr[data-robot]');
if (!tr) return null;
const h = document.querySelector('h1').getBoundingClientRect();
return {cells: Array.from(tr.cells).map((td) => td.innerText.trim()),
        right: Math.max(...Array.from(tr.cells).map((td) => td.getBoundingClientRect().right)),
        count: window.statusPage.count(191724964), bytes: window.statusPage.bytes(191724964),
        window: document.getElementById('rate-window').innerText};
"""
_ROBOT_PAGE = """
const h1 = document.querySelector('h1');
const box = h1.getBoundingClientRect();
return {title: document.title, h1: h1.innerText, h1_top: box.top,
        relay: document.getElementById('relay-meta').hidden ? null
          : document.getElementById('relay-meta').innerText,
        workers_shown: !document.getElementById('workers-section').hidden,
        uplink: document.getElementById('uplink-section').hidden ? null
          : document.getElementById('uplink').innerText,
        updates: Number(document.body.dataset.updates || 0)};
"""
_RATE = re.compile(r"\d[\d,]*\.\d msg/s")
_TOTAL = re.compile(r"\d[\d,]* msg")
_BYTES = re.compile(r"\d[\d,.]* (B|KB|MB|GB)")


def _browse(relay: str, robot_own: str) -> dict[str, Any]:
    """The relay's page (its robot row, once it shows rates), then the robot's page through
    the relay, then the robot's own bridge page; screenshots of each."""
    from selenium.webdriver.support.ui import WebDriverWait

    seen: dict[str, Any] = {}
    with headless_chromium("glance-relay") as driver:
        driver.set_window_size(1280, 900)
        driver.get(relay)
        seen["row"] = WebDriverWait(driver, 30, poll_frequency=0.2).until(
            lambda d: (r := d.execute_script(_ROW)) and _RATE.search(r["cells"][4])
            and not r["cells"][4].startswith("0.0") and r)
        seen["relay_overflow"] = driver.execute_script(OVERFLOW)
        shot(driver, "glance_relay_1280")
        for key, url in (("through_relay", relay + f"robots/{ROBOT}/"), ("own", robot_own)):
            driver.get(url)
            seen[key] = WebDriverWait(driver, 30, poll_frequency=0.1).until(
                lambda d: (r := d.execute_script(_ROBOT_PAGE))["updates"] >= 1 and r)
            seen[key + "_overflow"] = driver.execute_script(OVERFLOW)
            shot(driver, f"glance_robot_{key}_1280")
    return seen


async def test_relay_and_robot_pages_read_at_a_glance(ros_node: Any, topic: str) -> None:
    """At 1280 px the relay's robot row shows msg/s and bytes with units beside the totals, and
    fits; the robot's pages (through the relay, and its own) carry its name in their title and
    heading; through the relay the relay's process is shown apart, not as a worker of the robot."""
    pub = ros_node.create_publisher(String, topic, 10)
    ros_node.create_timer(0.1, lambda: pub.publish(String(data="tick")))
    async with tier(websocket=True) as t:
        t.robot.web.extra_status.append(t.exporter.status)  # as the robot's CLI does
        ws = await open_wire(t.url())

        async def drain() -> None:
            while True:
                await ws.ws.recv()

        draining = asyncio.create_task(drain())
        try:
            await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String"})
            base = f"http://127.0.0.1:{t.relay.port}/"
            seen = await asyncio.to_thread(_browse, base, f"http://127.0.0.1:{t.robot.port}/")
            code, _, body = await aget(base + "status.json")
        finally:
            draining.cancel()
            await ws.close()
    assert code == 200 and b'"rate_window_s":5' in body, body[:300]
    row = seen["row"]
    cells = row["cells"]
    # robot, on Zenoh, clients, topics watched, from robot, to clients, from clients, ...
    assert cells[:4] == [ROBOT, "yes", "1", topic], cells
    for cell in cells[4:6]:  # messages: the rate over the total; bytes: the same, in units
        assert _RATE.search(cell) and _TOTAL.search(cell) and _BYTES.search(cell), cells
    assert row["count"] == "191,724,964" and row["bytes"] == "191.7 MB", row
    assert row["window"] == "Rates are averaged over the last 5 s.", row
    assert row["right"] <= 1280, row
    for key in ("relay_overflow", "through_relay_overflow", "own_overflow"):
        width, window, scrolled = seen[key]
        assert width <= window and scrolled <= 0, (key, seen[key])
    through, own = seen["through_relay"], seen["own"]
    assert through["title"] == f"{ROBOT} \u00b7 roslibpy-lite relay", through
    assert through["h1"].startswith(ROBOT) and through["h1_top"] < 60, through
    assert through["relay"] is not None and t.relay.relay_id in through["relay"], through
    assert not through["workers_shown"], through
    assert own["title"] == f"{ROBOT} \u00b7 roslibpy-lite bridge", own
    assert own["uplink"] is not None and f"robot {ROBOT}" in own["uplink"], own
