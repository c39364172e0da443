"""Several URLs: the client moves to the next server when its server dies.

Two real bridge processes on one ROS graph (as two relays serving one robot would be),
rclpy nodes in this process, the client given both URLs. Killing the bridge it is on
moves it to the other at once (not back to the dead one), with its subscriptions and
publishers restored there.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import Any

import pytest

import roslibpy_lite
from roslibpy_lite import ConnectError, ConnectionState, UsageError
from tests.bridge.support import Inbox, until_heard
from tests.client.support import fast_backoff
from tests.helpers import BridgeProcess

with warnings.catch_warnings():
    warnings.filterwarnings("ignore", "module 'sre_.*' is deprecated", DeprecationWarning)
    import rosidl_generator_py  # noqa: F401

from std_msgs.msg import String as RosString


async def test_a_dead_server_hands_the_client_to_the_next(
    make_bridge: Callable[..., BridgeProcess], ros_node: Any, topic: str
) -> None:
    first, second = make_bridge(), make_bridge()
    ros_pub = ros_node.create_publisher(RosString, topic, 10)
    heard_by_ros = Inbox()
    ros_node.create_subscription(RosString, f"{topic}_back", lambda m: heard_by_ros(m.data), 10)
    async with roslibpy_lite.connect([first.url, second.url], backoff=fast_backoff()) as client:
        assert client.url == first.url and client.urls == (first.url, second.url)
        inbox = Inbox()
        client.subscribe(topic, "std_msgs/msg/String", callback=lambda m: inbox(m["data"]))
        pub = await client.advertise(f"{topic}_back", "std_msgs/msg/String")
        await until_heard(lambda: ros_pub.publish(RosString(data="before")), inbox, "before")
        async with client.state_changes() as changes:
            first.kill()
            while client.state is not ConnectionState.RECONNECTING:
                await changes.next(30)
            # The first bridge stays dead: only moving on brings the client back.
            while client.state is not ConnectionState.CONNECTED:  # type: ignore[comparison-overlap]
                await changes.next(30)
        assert client.url == second.url
        await until_heard(lambda: ros_pub.publish(RosString(data="after")), inbox, "after")
        await until_heard(lambda: pub.publish({"data": "back"}), heard_by_ros, "back")


async def test_the_first_connection_tries_each_in_turn(
    make_bridge: Callable[..., BridgeProcess], unused_tcp_port: int
) -> None:
    dead = f"ws://127.0.0.1:{unused_tcp_port}"
    live = make_bridge()
    async with roslibpy_lite.connect([dead, live.url], backoff=fast_backoff(),
                                     open_timeout=20) as client:
        assert client.url == live.url


async def test_none_answering_names_them_all(unused_tcp_port_factory: Any) -> None:
    urls = [f"ws://127.0.0.1:{unused_tcp_port_factory()}" for _ in range(2)]
    with pytest.raises(ConnectError, match=f"cannot connect to any of {urls[0]}, {urls[1]}"):
        await roslibpy_lite.connect(urls, backoff=fast_backoff(), open_timeout=0.5)


async def test_no_url_at_all() -> None:
    with pytest.raises(UsageError, match="no URL"):
        await roslibpy_lite.connect([])
