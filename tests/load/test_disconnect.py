"""What a client owned when it disconnects: subscriptions and services go at once, publishers after a grace."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest
from rclpy.event_handler import SubscriptionEventCallbacks
from std_msgs.msg import String
from std_srvs.srv import SetBool

from tests.bridge.support import Inbox, publish_until_heard, wait_publishers, wait_service
from tests.helpers import async_wait_until
from tests.load.support import service_in_graph, wait_count

pytestmark = pytest.mark.asyncio


async def _disconnected(bridge: Any, start: int) -> None:
    """Wait until the bridge logs that a client went away (after its clean-up ran)."""
    await asyncio.to_thread(bridge.wait_for_line, r"client \d+ .*disconnected", 10.0, start)


async def test_subscription_goes_at_once_publisher_stays_during_grace(
    make_bridge: Any, ws_connect: Any, ros_node: Any, topic: str
) -> None:
    """On disconnect the client's subscription leaves the graph while its publisher lives on (grace 30 s)."""
    bridge = make_bridge("--publisher-grace", "30")
    pub_topic, sub_topic = f"{topic}/out", f"{topic}/in"
    ws = await ws_connect(bridge.url)
    await ws.send({"op": "advertise", "topic": pub_topic, "type": "std_msgs/msg/String"})
    await ws.send({"op": "subscribe", "topic": sub_topic, "type": "std_msgs/msg/String"})
    await wait_count(ros_node.count_publishers, pub_topic, 1)
    await wait_count(ros_node.count_subscribers, sub_topic, 1)
    mark = len(bridge.lines)
    await ws.close()
    await _disconnected(bridge, mark)
    await wait_count(ros_node.count_subscribers, sub_topic, 0)
    assert ros_node.count_publishers(pub_topic) == 1


async def test_publisher_released_after_grace_kept_by_quick_readvertise(
    make_bridge: Any, ws_connect: Any, ros_node: Any, topic: str
) -> None:
    """After a disconnect the publishers outlive a short grace; one re-advertised by a quick reconnect never goes away."""
    bridge = make_bridge("--publisher-grace", "2.5")
    kept, dropped = f"{topic}/kept", f"{topic}/dropped"
    matched: list[int] = []
    inbox = Inbox()

    def on_matched(status: Any) -> None:
        matched.append(int(status.current_count))

    sub = ros_node.create_subscription(
        String, kept, inbox, 10,
        event_callbacks=SubscriptionEventCallbacks(matched=on_matched),
    )
    first = await ws_connect(bridge.url)
    for t in (kept, dropped):
        await first.send({"op": "advertise", "topic": t, "type": "std_msgs/msg/String"})
    await wait_publishers(sub)
    await wait_count(ros_node.count_publishers, dropped, 1)
    mark = len(bridge.lines)
    await first.close()
    await _disconnected(bridge, mark)
    assert ros_node.count_publishers(kept) == 1, "publishers must outlive the disconnect"
    assert ros_node.count_publishers(dropped) == 1, "publishers must outlive the disconnect"
    second = await ws_connect(bridge.url)
    await second.send({"op": "advertise", "topic": kept, "type": "std_msgs/msg/String"})
    # the first client's grace is over once its other publisher is gone
    await wait_count(ros_node.count_publishers, dropped, 0)
    assert ros_node.count_publishers(kept) == 1
    assert sub.get_publisher_count() == 1
    assert 0 not in matched, f"the kept topic lost its publisher for a while: {matched}"
    # The subscription seeing the publisher (above) does not prove the publisher sees it.
    heard = await publish_until_heard(second, kept, {"data": "still here"}, inbox)
    assert heard.data == "still here"


async def test_served_service_goes_at_once_and_no_default_is_invented(
    ws_connect: Any, ros_node: Any, topic: str
) -> None:
    """A served service leaves the graph when its client goes; a waiting ROS caller gets no default."""
    ws = await ws_connect()
    await ws.send({"op": "advertise_service", "service": topic, "type": "std_srvs/srv/SetBool"})
    client = ros_node.create_client(SetBool, topic)
    await wait_service(client)
    future = client.call_async(SetBool.Request(data=True))
    request = await ws.expect(op="call_service", service=topic)
    assert request["args"] == {"data": True}
    await ws.close()
    await async_wait_until(lambda: not client.service_is_ready(), 10.0, f"{topic} to go away")
    assert not future.done()
    client.remove_pending_request(future)
    # rmw_fastrtps lists a service while any client of it exists: drop ours before looking
    ros_node.destroy_client(client)
    await async_wait_until(lambda: not service_in_graph(ros_node, topic), 10.0,
                           f"{topic} to leave the graph")
