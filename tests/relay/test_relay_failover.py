"""A client given two relays moves to the other when its relay dies (issue 26).

One relay is the Zenoh router; two more are its clients, both serving the robot; our
client is given the two. When the one it is on goes, it is on the other within seconds,
its subscription restored, and from then on it gets every message the robot publishes.
"""

from __future__ import annotations

import asyncio
from typing import Any

import pytest
from std_msgs.msg import String

import roslibpy_lite
from roslibpy_lite import ConnectionState
from tests.client.support import fast_backoff
from tests.relay.support import ROBOT, free_port, robot_reachable, start_relay, start_robot

pytestmark = pytest.mark.timeout(90)


async def test_a_dead_relay_hands_its_clients_to_the_next(ros_node: Any, topic: str) -> None:
    router = f"tcp/127.0.0.1:{free_port()}"
    hub = await start_relay(listen=router)
    robot, exporter = await start_robot(router)
    first, second = await start_relay(router=router), await start_relay(router=router)
    pub = ros_node.create_publisher(String, topic, 100)
    try:
        for relay in (first, second):
            await robot_reachable(relay)
        urls = [f"ws://127.0.0.1:{r.port}/{ROBOT}" for r in (first, second)]
        async with roslibpy_lite.connect(urls, backoff=fast_backoff()) as ros:
            got: list[int] = []
            ros.subscribe(topic, "std_msgs/msg/String",
                          callback=lambda m: got.append(int(m["data"])), queue_length=100)
            n = 0

            async def publish_until(done: Any, what: str) -> None:
                nonlocal n
                deadline = asyncio.get_running_loop().time() + 30
                while not done():
                    n += 1
                    pub.publish(String(data=str(n)))
                    await asyncio.sleep(0.01)
                    assert asyncio.get_running_loop().time() < deadline, what

            await publish_until(lambda: got, "the first relay's client never heard the robot")
            assert ros.url == urls[0]
            await first.close()  # the relay dies
            # its second connection, up (RECONNECTING can be over between two looks)
            await publish_until(lambda: ros.connects > 1
                                and ros.state is ConnectionState.CONNECTED,
                                "the client never reached the second relay")
            assert ros.url == urls[1]
            heard_before = len(got)
            await publish_until(lambda: len(got) > heard_before, "nothing through the second")
            back_at = got[heard_before]
            target = n + 50
            await publish_until(lambda: got[-1] >= target, "the messages after the move")
            after = got[heard_before:]
            assert after == list(range(back_at, after[-1] + 1)), "a message after the move lost"
    finally:
        for relay in (second, first, hub):
            await relay.close()
        await exporter.close()
        await robot.close()
