"""A bridge's background loops end when they are cancelled, whatever they were doing.

On Python 3.11, ``asyncio.wait_for`` drops a cancel that arrives in the loop turn in which the
awaited event is set: a loop around it then runs on, and :meth:`Bridge.close`, which awaits
the cancelled task, never returns (the bridge hung on SIGTERM, most often on uvloop). These
tests cancel each loop in exactly that turn."""

from __future__ import annotations

import asyncio
import json
import os
from collections.abc import AsyncIterator

import pytest
import websockets

from bridge_server.front.server import Bridge, BridgeConfig
from bridge_server.rclpy_graph.graph import RclpyGraph
from tests.helpers import async_wait_until


@pytest.fixture
async def bridge() -> AsyncIterator[Bridge]:
    """An in-process bridge on an ephemeral port whose refresh loop sleeps long between looks."""
    config = BridgeConfig(port=0, refresh_interval=60.0, node_name=f"shutdown_{os.getpid()}")
    served = Bridge(config, RclpyGraph(asyncio.get_running_loop(), name=config.node_name))
    await served.start()
    try:
        yield served
    finally:
        if not served.closing:
            await asyncio.wait_for(served.close(), 10)


async def _cancelled_as_woken(task: asyncio.Task[None], wake: asyncio.Event) -> None:
    """Wake ``task``'s wait, let the wait end, cancel the task in that turn; it must end."""
    wake.set()
    await asyncio.sleep(0)  # the event's waiter is done; the task has not run on yet
    task.cancel()
    done, _ = await asyncio.wait([task], timeout=5)
    assert done, "the cancelled task ran on: its wait dropped the cancel"
    assert task.cancelled()


async def test_close_ends_the_refresh_loop_cancelled_as_the_graph_changes(bridge: Bridge) -> None:
    """The refresh loop waiting out its interval (something is subscribed) is cancelled in
    the turn a graph change wakes it; it ends, and the bridge closes."""
    async with websockets.connect(f"ws://127.0.0.1:{bridge.port}") as ws:
        await ws.send(json.dumps({"op": "subscribe", "topic": "/shutdown_chatter",
                                  "type": "std_msgs/msg/String"}))
        await async_wait_until(lambda: bridge.ros.subscriptions, what="the bridge's subscription")
        for _ in range(3):  # into the timed wait
            await asyncio.sleep(0)
        refresher = bridge._refresher
        assert refresher is not None
        await _cancelled_as_woken(refresher, bridge._graph_event)
    await asyncio.wait_for(bridge.close(), 10)


async def test_the_foxglove_hub_loop_ends_cancelled_as_it_is_poked(bridge: Bridge) -> None:
    """The Foxglove hub's graph loop is cancelled in the turn a poke wakes it; it ends."""
    hub = bridge.foxglove
    task = asyncio.create_task(hub._run(), name="foxglove-hub-test")
    for _ in range(3):
        await asyncio.sleep(0)
    await _cancelled_as_woken(task, hub._wake)
