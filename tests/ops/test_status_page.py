"""The live status page in a real headless Chromium (Debian's chromium + chromium-driver)."""

from __future__ import annotations

import asyncio
import shutil
import tempfile
from typing import Any

import pytest

from tests.bridge.support import wait_subscribers
from tests.helpers import ROOT, BridgeProcess, open_wire

CHROMIUM = shutil.which("chromium")
DRIVER = shutil.which("chromedriver")
ARTIFACTS = ROOT / "tests" / "artifacts"
NO_VALUE = "\u2013"  # what the page shows for a rate not measured yet (an en dash)

pytestmark = pytest.mark.skipif(
    CHROMIUM is None or DRIVER is None,
    reason="chromium and chromium-driver are not installed (scripts/setup.sh installs them)",
)


_READ_PAGE = """
const rows = (id) => Array.from(document.querySelectorAll('#' + id + ' tbody tr'))
    .map((tr) => Array.from(tr.cells).map((td) => td.innerText.trim()));
const text = (id) => document.getElementById(id).innerText;
return {clients: text('client-count'), version: text('version'), uptime: text('uptime'),
        topics: rows('topics'), client_rows: rows('clients').map((r) => r.join(' ')),
        services: rows('services').map((r) => r.join(' ')),
        actions: rows('actions'),
        plot_points: document.querySelector('#rates-plot .to-clients')
          .getAttribute('points').trim().split(' ').filter((p) => p).length,
        rates_now: text('rates-now'),
        updates: Number(document.body.dataset.updates || 0)};
"""


def _browse(url: str, topic: str, service: str, shots: dict[str, tuple[int, int]]) -> dict[str, Any]:
    """Load the page, wait for live figures, read what it shows, save screenshots."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    from selenium.webdriver.support.ui import WebDriverWait

    options = webdriver.ChromeOptions()
    assert CHROMIUM is not None and DRIVER is not None
    options.binary_location = CHROMIUM
    profile = tempfile.mkdtemp(prefix="status-page-chromium-")
    for arg in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                "--disable-component-update", "--disable-sync", "--no-first-run",
                "--disable-dev-shm-usage", f"--user-data-dir={profile}"):
        options.add_argument(arg)
    driver = webdriver.Chrome(options=options, service=Service(executable_path=DRIVER))
    try:
        driver.set_window_size(1280, 900)
        driver.get(url)

        def read(d: Any) -> dict[str, Any]:
            # One script reads the page at once: the tables are redrawn every second.
            return dict(d.execute_script(_READ_PAGE))

        def live_rate(d: Any) -> Any:
            page = read(d)
            for cells in page["topics"]:
                if cells and cells[0] == topic and cells[3] not in (NO_VALUE, "0.0"):
                    return page
            return False

        seen: dict[str, Any] = WebDriverWait(driver, 20, poll_frequency=0.1).until(live_rate)
        seen["topic_row"] = next(c for c in seen["topics"] if c[0] == topic)
        # It keeps updating by itself.
        before = seen["updates"]
        WebDriverWait(driver, 10, poll_frequency=0.1).until(
            lambda d: read(d)["updates"] > before)
        ARTIFACTS.mkdir(exist_ok=True)
        for name, (w, h) in shots.items():
            driver.set_window_size(w, h)
            WebDriverWait(driver, 10).until(lambda d: read(d)["clients"] == seen["clients"])
            path = ARTIFACTS / f"status_page_{name}.png"
            driver.save_screenshot(str(path))
            print(f"screenshot: {path}")
        seen["phone_table_display"] = driver.execute_script(
            "return getComputedStyle(document.querySelector('#clients thead')).display")
        seen["phone_overflow"] = driver.execute_script(
            "return document.documentElement.scrollWidth > window.innerWidth + 1")
        return seen
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


async def test_status_page_shows_live_clients_topics_and_services(
    make_bridge: Any, ros_node: Any, topic: str
) -> None:
    """With real clients on a real rclpy topic, the page shows them and live rates, on desktop and phone."""
    from std_msgs.msg import String

    b: BridgeProcess = make_bridge()
    pub = ros_node.create_publisher(String, topic, 10)
    ros_node.create_timer(1 / 20, lambda: pub.publish(String(data="tick")))
    from tests.bridge.action_support import FibServer, bridge_sees_action, send_goal

    service, action, gone = topic + "_srv", topic + "_act", ""
    fib_server = None
    readers = [await open_wire(b.url) for _ in range(2)]
    drains: list[asyncio.Task[None]] = []
    try:
        for ws in readers:
            await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String",
                           "queue_length": 5})
        await readers[1].send({"op": "advertise_service", "service": service,
                               "type": "std_srvs/srv/Trigger"})
        await wait_subscribers(pub)

        async def drain(ws: Any) -> None:
            while True:
                await ws.ws.recv()

        # A topic nobody uses any more leaves the table.
        gone = topic + "_gone"
        await readers[0].send({"op": "subscribe", "topic": gone, "type": "std_msgs/msg/String"})
        await readers[0].send({"op": "unsubscribe", "topic": gone})
        # Three goals that ran and ended: the actions table counts them after they are done.
        fib_server = FibServer(ros_node, action)
        await bridge_sees_action(readers[0], action)
        for i in range(3):
            await send_goal(readers[0], action, {"order": 2}, f"g{i}")
            result = await readers[0].expect(op="action_result", id=f"g{i}")
            assert result["status"] == 4, result
        drains = [asyncio.create_task(drain(ws)) for ws in readers]
        seen = await asyncio.to_thread(
            _browse, f"http://127.0.0.1:{b.port}/", topic, service,
            {"desktop": (1280, 900), "phone": (390, 844)},
        )
    finally:
        for task in drains:
            task.cancel()
        for ws in readers:
            await ws.close()
        if fib_server is not None:
            fib_server.destroy()
    assert seen["clients"] == "2"
    assert not [c for c in seen["topics"] if c and c[0] == gone], seen["topics"]
    assert seen["plot_points"] >= 2 and "/s to clients" in seen["rates_now"], seen
    row = next(r for r in seen["actions"] if r[0] == action)
    assert (row[2], row[3]) == ("ROS", "3"), seen["actions"]  # 3 goals ran and ended
    assert seen["version"] == "0.1.0"
    _name, type_name, subscribers, from_ros, to_clients = seen["topic_row"][:5]
    assert (type_name, subscribers) == ("std_msgs/msg/String", "2")
    assert 5.0 <= float(from_ros) <= 40.0 and float(to_clients) > 0  # about 20 /s
    assert len(seen["client_rows"]) == 2
    assert all("127.0.0.1:" in row and topic in row for row in seen["client_rows"])
    assert any(service in row and "std_srvs/srv/Trigger" in row for row in seen["services"])
    # On a phone-sized screen the tables become cards and nothing scrolls sideways.
    assert seen["phone_table_display"] == "none"
    assert seen["phone_overflow"] is False
