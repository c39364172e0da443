"""A viewer that subscribes hears what the robot publishes from then on, not its window.

The robot keeps a window of each reliable topic's last messages for relays whose link
drops (:mod:`bridge_server.zenoh.replay`). A relay's new subscription to the topic must not
hand its viewer that window: what the robot published before anyone on this relay asked is
not the viewer's to hear (a volatile topic's ROS subscriber would not hear it either). The
window is there when the topic is still watched elsewhere, or was until a moment ago (its
linger): a page reloaded, a client that reconnects, a relay restarted while another relay's
viewers kept the topic going.
"""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

import roslibpy_lite
from bridge_server.zenoh import keys
from bridge_server.zenoh.graph import ZenohGraph
from tests.relay.support import ROBOT, tier, until

pytestmark = pytest.mark.timeout(90)


async def test_a_new_viewer_does_not_hear_the_window_of_a_topic_watched_before(
        ros_node: Any, topic: str) -> None:
    """Twenty messages go through the window while a first viewer watches; it leaves, and a
    second viewer subscribes while the robot still keeps the topic (its linger). Only once
    the robot's heartbeat of the topic has reached the relay twice (the relay's new
    subscription asks the robot what it missed at a heartbeat) is the next message
    published: the second viewer's first message is that one."""
    from std_msgs.msg import String

    pub = ros_node.create_publisher(String, topic, 10)  # reliable, volatile: replayed
    async with tier() as t:
        t.exporter.demand_linger = 60.0  # kept, with its window, while nobody watches
        async with roslibpy_lite.connect(t.url()) as ros:
            first = ros.subscribe(topic, "std_msgs/msg/String")
            while True:  # the robot's subscription matches the publisher in its own time
                pub.publish(String(data="probe"))
                try:
                    if (await first.get(0.2))["data"] == "probe":
                        break
                except TimeoutError:
                    continue
            for n in range(1, 21):
                pub.publish(String(data=f"old {n}"))
            heard = [(await first.get(10))["data"] for _ in range(20)]
            assert heard[-1] == "old 20", heard
            await first.unsubscribe()
        await until(lambda: not t.demand(topic), "the relay to stop watching the topic")
        export = t.exporter.exports[topic]
        assert export.replay is not None and export.replay.held >= 20  # the window is there

        assert t.relay.session is not None
        beats: asyncio.Queue[None] = asyncio.Queue()
        loop = asyncio.get_running_loop()
        heartbeat = t.relay.session.declare_subscriber(
            f"{keys.key_of(ROBOT, topic)}/{keys.ADV}/pub/**",
            lambda _: loop.call_soon_threadsafe(beats.put_nowait, None))
        try:
            async with roslibpy_lite.connect(t.url()) as ros:
                second = ros.subscribe(topic, "std_msgs/msg/String")
                await until(lambda: bool(t.demand(topic)), "the relay to watch the topic again")
                bridge = await t.relay.robot(ROBOT)
                assert bridge is not None and isinstance(bridge.graph, ZenohGraph)
                feed = bridge.graph.subscriptions[topic]
                await until(lambda: feed.placed, "the relay's subscription to know its place")
                while not beats.empty():
                    beats.get_nowait()
                for _ in range(2):  # each after the relay's subscription reached the robot
                    await asyncio.wait_for(beats.get(), 10)
                pub.publish(String(data="new 1"))
                got = (await second.get(10))["data"]
                assert got == "new 1", f"a new viewer first heard {got!r}, from the window"
        finally:
            heartbeat.undeclare()  # type: ignore[no-untyped-call]
