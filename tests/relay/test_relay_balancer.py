"""Several relays behind one TCP load balancer share the clients (issue 26 item 3).

One relay is the Zenoh router; two more, its clients, both serve the robot, behind a
round-robin TCP balancer (``bench.linkproxy.LinkProxy`` given both addresses). Our clients
all connect to the balancer's one address: they are spread over the two relays and all hear
the robot. When one relay dies its clients come back through the same address, the balancer
takes them to the other, their subscriptions are restored (the client's reconnect), and each
gets every message published after it is back.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable
from typing import Any

import pytest
from std_msgs.msg import String

import roslibpy_lite
from bench.linkproxy import LinkProxy
from roslibpy_lite import ConnectionState
from tests.client.support import fast_backoff
from tests.relay.support import ROBOT, free_port, robot_reachable, start_relay, start_robot

pytestmark = pytest.mark.timeout(120)

CLIENTS = 4


def _collect(heard: list[int]) -> Callable[[Any], None]:
    """A callback appending each message's number to ``heard``."""
    return lambda msg: heard.append(int(msg["data"]))


async def test_relays_behind_a_balancer_share_clients_and_take_over(ros_node: Any, topic: str
                                                                    ) -> None:
    """Four clients through one balancer address: two on each relay, all hear the robot; a
    relay killed, its two clients are back through the balancer on the other relay with
    their subscriptions and get every message published after that, in order."""
    router = f"tcp/127.0.0.1:{free_port()}"
    hub = await start_relay(listen=router)
    robot, exporter = await start_robot(router)
    relays = [await start_relay(router=router), await start_relay(router=router)]
    pub = ros_node.create_publisher(String, topic, 100)
    n = 0

    async def publish_until(done: Any, what: str, timeout: float = 30.0) -> None:
        nonlocal n
        deadline = asyncio.get_running_loop().time() + timeout
        while not done():
            n += 1
            pub.publish(String(data=str(n)))
            await asyncio.sleep(0.01)
            assert asyncio.get_running_loop().time() < deadline, what

    try:
        for relay in relays:
            await robot_reachable(relay)
        with LinkProxy([("127.0.0.1", r.port) for r in relays]) as balancer:
            url = f"ws://127.0.0.1:{balancer.port}/{ROBOT}"
            async with contextlib.AsyncExitStack() as stack:
                clients = [await stack.enter_async_context(
                    roslibpy_lite.connect(url, backoff=fast_backoff())) for _ in range(CLIENTS)]
                got: list[list[int]] = [[] for _ in clients]
                for ros, heard in zip(clients, got, strict=True):
                    ros.subscribe(topic, "std_msgs/msg/String", queue_length=100,
                                  callback=_collect(heard))
                assert list(balancer.carried.values()) == [2, 2], balancer.carried
                assert [len(r.robots[ROBOT].sessions) for r in relays] == [2, 2]
                await publish_until(lambda: all(got), "a client never heard the robot")

                dying, staying = relays
                await dying.close()

                def moved() -> list[int]:  # the clients that lost their relay
                    return [i for i, ros in enumerate(clients)
                            if ros.connects > 1 or ros.state is not ConnectionState.CONNECTED]

                await publish_until(lambda: len(moved()) == 2,
                                    "the dead relay's two clients never noticed")
                await publish_until(lambda: all(clients[i].state is ConnectionState.CONNECTED
                                                for i in moved()),
                                    "a client never came back through the balancer")
                assert len(moved()) == 2
                assert len(staying.robots[ROBOT].sessions) == CLIENTS
                heard_before = {i: len(got[i]) for i in moved()}
                await publish_until(lambda: all(len(got[i]) > heard_before[i] for i in moved()),
                                    "a moved client heard nothing through the other relay")
                target = n + 50
                await publish_until(lambda: all(g[-1] >= target for g in got),
                                    "the messages after the move")
                for i in moved():
                    after = got[i][heard_before[i]:]
                    assert after == list(range(after[0], after[-1] + 1)), \
                        f"client {i} lost a message after it was back"
                for i in set(range(CLIENTS)) - set(moved()):
                    assert got[i] == list(range(got[i][0], got[i][-1] + 1)), \
                        f"client {i}, on the relay that stayed, lost a message"
    finally:
        for relay in (*reversed(relays), hub):
            await relay.close()
        await exporter.close()
        await robot.close()
