"""The robot knows its uplink (issue 50, item 2): its log, status.json, /metrics, /readyz.

Real processes (:mod:`tests.relay.link_load`): a relay that is the router, the robot's
bridge with ``--no-websocket`` dialing it through a proxy, a counter on the robot and a
640x480 camera, both watched through the relay. The camera fills the link's buffers, so a
cut leaves Zenoh's own transport waiting on a write it cannot finish: Zenoh tells the robot
that its router went only when the link is back. The robot's own probe says it within the
lease.
"""

from __future__ import annotations

import datetime
import json
import time
import urllib.error
import urllib.request
from typing import Any

import pytest

import roslibpy_lite
from tests.relay.link_load import CAMERA, COUNT, ROBOT, Loaded, load_tier
from tests.relay.support import free_port, until

pytestmark = pytest.mark.timeout(120)

LEASE = 3.0
"""Seconds: the Zenoh lease (``--zenoh-lease``'s default)."""

GONE = "its uplink to the Zenoh network is gone"


def _get(url: str) -> tuple[int, str]:
    """The status and body of a GET of ``url``."""
    try:
        with urllib.request.urlopen(url, timeout=10) as reply:
            return reply.status, reply.read().decode()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read().decode()


def _logged_at(line: str) -> float:
    """The Unix time of a log line of the robot (its ``asctime``, local time)."""
    stamp = datetime.datetime.strptime(line[:23], "%Y-%m-%d %H:%M:%S,%f")
    return stamp.timestamp()


async def _watched(t: Loaded, ros: roslibpy_lite.Ros) -> None:
    """Our client watches the counter and the camera until both arrive."""
    got: dict[str, int] = {COUNT: 0, CAMERA: 0}

    def heard(topic: str) -> Any:
        return lambda _msg: got.__setitem__(topic, got[topic] + 1)

    ros.subscribe(COUNT, "std_msgs/msg/String", heard(COUNT), queue_length=100)
    ros.subscribe(CAMERA, "sensor_msgs/msg/Image", heard(CAMERA), raw=True, queue_length=1)
    await until(lambda: all(got.values()), "the counter and the camera to arrive", 30)


async def test_a_cut_uplink_is_logged_by_the_robot_within_the_lease() -> None:
    """The robot's link blackholed while a camera fills it: the robot logs at WARNING that
    its uplink is gone within the lease of the cut (not when the link comes back), and that
    it is back once it is."""
    with load_tier(camera=True) as t:
        async with roslibpy_lite.connect(t.url) as ros:
            await _watched(t, ros)
            seen = len(t.robot.lines)
            cut = time.time()
            t.link.blackhole()
            try:
                await until(lambda: any(GONE in line for line in t.robot.lines[seen:]),
                            "the robot to log its uplink gone", LEASE + 7)
            finally:
                t.link.restore()
            line = next(line for line in t.robot.lines[seen:] if GONE in line)
            assert " WARNING " in line and f"robot {ROBOT}:" in line, line
            assert _logged_at(line) - cut < LEASE, (line, cut)
            await until(lambda: any("uplink to the Zenoh network is back" in line
                                    for line in t.robot.lines[seen:]),
                        "the robot to log its uplink back", 30)


async def test_the_robots_status_and_metrics_show_its_uplink() -> None:
    """The robot's status.json names its robot, its router and its uplink (up, since when),
    what it sends to relays (messages and bytes, per second), its replay window's use and
    its refusals; a cut shows the uplink down; /metrics has the same."""
    mport = free_port()
    with load_tier("--metrics-port", str(mport), camera=True) as t:
        base = f"http://127.0.0.1:{mport}"
        async with roslibpy_lite.connect(t.url) as ros:
            await _watched(t, ros)

            def uplink() -> dict[str, Any]:
                return json.loads(_get(base + "/status.json")[1])["relay_uplink"]  # type: ignore[no-any-return]

            up = await until(lambda: (u := uplink())["messages_per_s"] > 0 and u,
                             "the rates to be measured", 15)
            assert up["robot"] == ROBOT and up["routers"] == [f"tcp/127.0.0.1:{t.link.port}"]
            assert up["up"] is True and up["admitted"] is True and up["refusal"] is None
            assert time.time() - 60 < up["since"] <= time.time()
            assert up["messages"] > 0 and up["bytes"] > 640 * 480 * 3, up
            assert up["replay"]["topics"] == 1 and up["replay"]["messages"] > 0, up
            assert up["refusals"] == {"policy": 0, "name": 0, "admission": 0}
            assert up["putting"]["dropped"] == 0 and up["putting"]["waiting_bytes"] >= 0, up
            metrics = _get(base + "/metrics")[1]
            assert f'roslibpy_bridge_relay_uplink_up{{robot="{ROBOT}"}} 1.0' in metrics
            assert f'roslibpy_bridge_relay_sent_messages_total{{robot="{ROBOT}"}}' in metrics
            assert f'roslibpy_bridge_relay_put_dropped_messages_total{{robot="{ROBOT}"}} 0.0' \
                in metrics
            t.link.blackhole()
            try:
                down = await until(lambda: (u := uplink())["up"] is False and u,
                                   "the status to show the uplink down", LEASE + 7)
                metrics = _get(base + "/metrics")[1]  # while the link is still cut
            finally:
                t.link.restore()
            assert down["lost"] == 1 and down["since"] > up["since"], down
            assert f'roslibpy_bridge_relay_uplink_up{{robot="{ROBOT}"}} 0.0' in metrics


async def test_readyz_without_a_websocket_follows_the_uplink() -> None:
    """With ``--no-websocket`` the robot's /readyz (on ``--metrics-port``) is 200 while its
    uplink is up, 503 naming the uplink while it is cut, and 200 again once it is back."""
    mport = free_port()
    with load_tier("--metrics-port", str(mport)) as t:
        readyz = f"http://127.0.0.1:{mport}/readyz"
        assert await until(lambda: _get(readyz)[0] == 200, "the robot to be ready", 15)
        t.link.blackhole()
        try:
            _code, body = await until(lambda: (r := _get(readyz))[0] == 503 and r,
                                     "readyz to say the uplink is down", LEASE + 7)
        finally:
            t.link.restore()
        assert "uplink to Zenoh" in body and "is down" in body, body
        await until(lambda: _get(readyz)[0] == 200, "the robot to be ready again", 30)
