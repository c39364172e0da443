"""Fan-out: many clients on one busy topic each receive every message."""

from __future__ import annotations

import asyncio
import contextlib
import json
from typing import Any

import pytest
from std_msgs.msg import String

from tests.bridge.support import wait_subscribers
from tests.helpers import async_wait_until
from tests.load.support import qos

pytestmark = pytest.mark.asyncio

CLIENTS = 50
MESSAGES = 200
RATE_HZ = 100


class _Counter:
    """One raw client's view of the topic: has it seen a probe, which numbers arrived, in order?"""

    def __init__(self) -> None:
        self.probed = False
        self.numbers: list[int] = []
        self.other: list[Any] = []

    def feed(self, op: Any) -> None:
        data = op.get("msg", {}).get("data", "") if op.get("op") == "publish" else None
        if data == "probe":
            self.probed = True
        elif isinstance(data, str) and data.startswith("n"):
            self.numbers.append(int(data[1:]))
        else:
            self.other.append(op)


async def test_fifty_clients_each_get_every_message(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """50 clients subscribed to one 100 Hz topic each receive all 200 numbered messages, in order."""
    pub = ros_node.create_publisher(String, topic, qos(depth=MESSAGES))
    clients = [await ws_connect() for _ in range(CLIENTS)]
    counters = [_Counter() for _ in clients]

    async def read(ws: Any, counter: _Counter) -> None:
        with contextlib.suppress(Exception):
            async for frame in ws.ws:
                counter.feed(json.loads(frame))

    for ws in clients:
        await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String",
                       "queue_length": MESSAGES})
    readers = [asyncio.create_task(read(ws, c)) for ws, c in zip(clients, counters, strict=True)]
    try:
        await wait_subscribers(pub)  # the bridge shares one ROS subscription among all clients
        # probes until every client is surely subscribed (there is no per-client graph event)
        while not all(c.probed for c in counters):
            pub.publish(String(data="probe"))
            await asyncio.sleep(0.02)
        for i in range(MESSAGES):
            pub.publish(String(data=f"n{i}"))
            await asyncio.sleep(1 / RATE_HZ)  # pacing the publisher, not synchronisation
        await async_wait_until(
            lambda: all(len(c.numbers) >= MESSAGES for c in counters), 15.0,
            "every client to receive every message",
        )
    finally:
        for task in readers:
            task.cancel()
        await asyncio.gather(*readers, return_exceptions=True)
    short = {i: len(c.numbers) for i, c in enumerate(counters) if c.numbers != list(range(MESSAGES))}
    assert short == {}, f"clients missing or reordering messages (client: count): {short}"
    assert all(c.other == [] for c in counters), [c.other[:2] for c in counters if c.other][:3]
