"""The CDR bomb of issue 39 through a relay: a robot puts samples of a type with a sequence of
an empty message (``test_msgs/msg/UnboundedSequences``: ``constants_values`` is a sequence of
``test_msgs/Constants``, which has no fields) whose count claims millions of elements in 73
bytes. The relay (a child process) decodes them for its JSON client without its peak RSS
rising past RSS_BOUND, and another robot's viewer keeps getting its messages."""

from __future__ import annotations

import asyncio
import itertools
import re
import sys
from typing import Any

import pytest

from tests.helpers import open_wire, peak_rss, ros_env
from tests.msgs.test_cdr_bounds import bomb
from tests.ops.support import aget
from tests.relay.procs import Proc
from tests.relay.support import free_port, start_robot

pytestmark = pytest.mark.timeout(90)

COUNT = 3_000_000
"""Empty messages each bomb claims: before the fix the relay built a dict for each (~220 MB a
sample)."""
BOMBS = 8
"""Bombs the robot puts, as in the issue's report."""
RSS_BOUND = 64 * 2**20
"""How far the relay's peak RSS may rise while it handles the bombs."""
READY = re.compile(r"relay listening on ws://127\.0\.0\.1:(\d+)")


async def test_a_robots_cdr_bombs_cost_the_relay_no_memory(ros_node: Any, topic: str) -> None:
    """Eight 73-byte samples each claiming 3x10^6 empty messages, put by robot1 and decoded
    by the relay for a JSON client: the relay's peak RSS rises by less than RSS_BOUND, the
    samples after them still reach that client, and robot2's viewer keeps receiving."""
    from std_msgs.msg import Int32
    from test_msgs.msg import UnboundedSequences

    router = f"tcp/127.0.0.1:{free_port()}"
    relay = Proc([sys.executable, "-m", "bridge_server.zenoh.relay", "--port", "0",
                  "--zenoh-listen", router], ros_env())
    robots = []
    beat_topic, bomb_topic = topic + "_beat", topic + "_bomb"
    beats = itertools.count()
    sent = [0]
    beat_pub = ros_node.create_publisher(Int32, beat_topic, 10)
    bomb_pub = ros_node.create_publisher(UnboundedSequences, bomb_topic, 10)

    def beat() -> None:
        sent[0] = next(beats)
        beat_pub.publish(Int32(data=sent[0]))

    timer = ros_node.create_timer(0.02, beat)
    try:
        port = int(relay.wait_for(READY).group(1))
        robots = [await start_robot(router, robot=name) for name in ("robot1", "robot2")]
        for name in ("robot1", "robot2"):
            await _until_served(port, name)
        viewer = await open_wire(f"ws://127.0.0.1:{port}/robot2")
        attacked = await open_wire(f"ws://127.0.0.1:{port}/robot1")
        await viewer.send({"op": "subscribe", "topic": beat_topic, "type": "std_msgs/msg/Int32"})
        try:
            await viewer.expect(op="publish", topic=beat_topic, timeout=30)
        except AssertionError as exc:  # say what the relay and the robots saw
            ups = {r.robot: (r.uplink.up, r.uplink.lost) for _, r in robots}
            raise AssertionError(f"{exc}\nrobots' uplinks (up, times lost): {ups}\nthe "
                                 "relay's log:\n" + "\n".join(list(relay.lines)[-40:])
                                 ) from None
        await attacked.send({"op": "subscribe", "topic": bomb_topic,
                             "type": "test_msgs/msg/UnboundedSequences"})
        good = UnboundedSequences(int32_values=[1])
        for _ in range(300):  # until the robot's subscription matched and the client hears it
            bomb_pub.publish(good)
            try:
                await attacked.expect(op="publish", topic=bomb_topic, timeout=0.1)
                break
            except AssertionError:
                continue
        peak_before = peak_rss(relay.proc.pid)
        data = bomb(COUNT)
        for _ in range(BOMBS):
            bomb_pub.publish(data)  # rclpy publishes bytes as the serialized message
        bomb_pub.publish(UnboundedSequences(int32_values=[2]))
        after_bombs = await attacked.expect(
            lambda op: op["msg"]["int32_values"] == [2], op="publish", topic=bomb_topic,
            timeout=30)
        assert after_bombs["msg"]["constants_values"] == []
        rise = peak_rss(relay.proc.pid) - peak_before
        assert rise < RSS_BOUND, f"the relay's peak RSS rose by {rise / 2**20:.0f} MiB"
        now = sent[0]
        viewer.backlog.clear()
        await viewer.expect(lambda op: op["msg"]["data"] > now, op="publish", topic=beat_topic,
                            timeout=30)
        await viewer.close()
        await attacked.close()
    finally:
        ros_node.destroy_timer(timer)
        relay.stop()
        for bridge, exporter in robots:
            await exporter.close()
            await bridge.close()


async def _until_served(port: int, robot: str, timeout: float = 30.0) -> None:
    """Wait until the relay on ``port`` serves ``robot`` (its readyz answers 200; Zenoh
    liveliness has no event here)."""
    deadline = asyncio.get_running_loop().time() + timeout
    while True:
        try:
            if (await aget(f"http://127.0.0.1:{port}/{robot}/readyz"))[0] == 200:
                return
        except OSError:
            pass
        assert asyncio.get_running_loop().time() < deadline, f"the relay never served {robot}"
        await asyncio.sleep(0.1)
