"""The live status page in a real headless Chromium (Debian's chromium + chromium-driver)."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any

import pytest

from tests.bridge.action_support import FIB, FibServer, bridge_sees_action, send_goal
from tests.bridge.support import wait_subscribers
from tests.helpers import CHROMEDRIVER, CHROMIUM, ROOT, BridgeProcess, headless_chromium, open_wire

ARTIFACTS = ROOT / "tests" / "artifacts"
NO_VALUE = "\u2013"  # what the page shows for a rate not measured yet (an en dash)

pytestmark = pytest.mark.skipif(
    CHROMIUM is None or CHROMEDRIVER is None,
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


def _browse(url: str, missing: Callable[[dict[str, Any]], list[str]],
            shots: dict[str, tuple[int, int]]) -> dict[str, Any]:
    """Load the page, wait (up to a deadline) until it shows all the test expects
    (``missing`` of a reading is empty), read it, save screenshots.

    The reading returned has ``missing``: what the page still lacked at the deadline.
    """
    from selenium.common.exceptions import TimeoutException
    from selenium.webdriver.support.ui import WebDriverWait

    with headless_chromium("status-page") as driver:
        driver.set_window_size(1280, 900)
        driver.get(url)

        def read(d: Any) -> dict[str, Any]:
            # One script reads the page at once: the tables are redrawn every second.
            page = dict(d.execute_script(_READ_PAGE))
            page["missing"] = missing(page)
            return page

        last: dict[str, Any] = {}

        def shows_all(d: Any) -> Any:
            last.update(read(d))
            return dict(last) if not last["missing"] else False

        try:
            seen: dict[str, Any] = WebDriverWait(driver, 30, poll_frequency=0.1).until(shows_all)
        except TimeoutException:
            return last  # the test's assertion shows what never appeared
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


def _per_s(cell: str) -> float:
    """The messages per second of a rate cell (``20.0 msg/s``, maybe ``· 1.2 KB/s`` after)."""
    return float(cell.split(" msg/s", 1)[0].replace(",", ""))


def _missing(page: dict[str, Any], topic: str, gone: str, service: str, action: str,
             served_action: str, served_by: str) -> list[str]:
    """What of the test's clients, topics, services and actions ``page`` does not show (yet)."""
    missing = []
    rows = {cells[0]: cells for cells in page["topics"] if cells}
    row = rows.get(topic, [])
    # name, type, subscribers, from ROS /s, to clients /s: about 20 /s
    if len(row) < 5 or row[1:3] != ["std_msgs/msg/String", "2"] or NO_VALUE in row[3:5] or not (
            5.0 <= _per_s(row[3]) <= 40.0 and _per_s(row[4]) > 0):
        missing.append(f"a live rate of about 20 /s for {topic}: {row}")
    if gone in rows:
        missing.append(f"{gone} left the topics table")
    if page["plot_points"] < 2 or "/s to clients" not in page["rates_now"]:
        missing.append(f"a plot of 2 points or more: {page['plot_points']}, {page['rates_now']}")
    if page["clients"] != "2" or len(page["client_rows"]) != 2 or not all(
            "127.0.0.1:" in r and topic in r for r in page["client_rows"]):
        missing.append(f"the 2 clients: {page['clients']}, {page['client_rows']}")
    if not any(service in r and "std_srvs/srv/Trigger" in r for r in page["services"]):
        missing.append(f"the served service: {page['services']}")
    actions = {cells[0]: cells for cells in page["actions"] if cells}
    # name, type, served by, goals: 3 goals that ran and ended; a client-served one idle
    if actions.get(action) != [action, FIB, "ROS", "3"]:
        missing.append(f"{action} of {FIB} served by ROS, 3 goals: {actions.get(action)}")
    if actions.get(served_action) != [served_action, FIB, served_by, "0"]:
        missing.append(f"{served_action} of {FIB} served by client {served_by}: "
                       f"{actions.get(served_action)}")
    return missing


async def test_status_page_shows_live_clients_topics_and_services(
    make_bridge: Any, ros_node: Any, topic: str
) -> None:
    """With real clients on a real rclpy topic, the page shows them and live rates, on desktop and phone."""
    from std_msgs.msg import String

    b: BridgeProcess = make_bridge()
    pub = ros_node.create_publisher(String, topic, 10)
    ros_node.create_timer(1 / 20, lambda: pub.publish(String(data="tick")))

    service, action, served_action = topic + "_srv", topic + "_act", topic + "_served_act"
    gone = topic + "_gone"
    fib_server = None
    readers = [await open_wire(b.url) for _ in range(2)]
    drains: list[asyncio.Task[None]] = []
    try:
        for ws in readers:
            await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String",
                           "queue_length": 5})
        await readers[1].send({"op": "advertise_service", "service": service,
                               "type": "std_srvs/srv/Trigger"})
        await readers[1].send({"op": "advertise_action", "action": served_action, "type": FIB})
        await wait_subscribers(pub)

        async def drain(ws: Any) -> None:
            while True:
                await ws.ws.recv()

        # A topic nobody uses any more leaves the table.
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
            _browse, f"http://127.0.0.1:{b.port}/",
            lambda page: _missing(page, topic, gone, service, action, served_action, "0-2"),
            {"desktop": (1280, 900), "phone": (390, 844)},
        )
    finally:
        for task in drains:
            task.cancel()
        for ws in readers:
            await ws.close()
        if fib_server is not None:
            fib_server.destroy()
    assert seen["missing"] == [], seen
    assert seen["version"] == "0.1.0"
    # On a phone-sized screen the tables become cards and nothing scrolls sideways.
    assert seen["phone_table_display"] == "none"
    assert seen["phone_overflow"] is False
