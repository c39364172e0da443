"""A Foxglove session on its ports: the same in-memory link and graph as a rosbridge session
(tests/session/harness.py), sharing a never-started ``Bridge``'s state (its Foxglove hub is
the server's, a floor above the core's MemoryServer). No ROS, no socket."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

from bridge_server.foxglove.session import FoxgloveSession
from bridge_server.front.server import Bridge, BridgeConfig
from rosbridge_core.memory.graph import MemoryGraph, MemoryRos
from tests.session.harness import Client


@asynccontextmanager
async def open_foxglove(client: Client | None = None
                        ) -> AsyncIterator[tuple[FoxgloveSession, Client, MemoryGraph]]:
    """A Foxglove session running over ``client``'s link, sharing a never-started bridge's
    state over the node ``rosbridge`` of a new in-memory graph."""
    graph = MemoryRos().node("rosbridge")
    bridge = Bridge(BridgeConfig(), graph)
    client = client or Client()
    session = FoxgloveSession(bridge, bridge.foxglove, client.link, 1)
    running = asyncio.create_task(session.run())
    try:
        yield session, client, graph
    finally:
        client.hang_up()
        await asyncio.wait_for(running, 5.0)
        await bridge.foxglove.close()
        graph.close()


async def test_a_foxglove_client_is_greeted_and_bad_frames_get_a_status() -> None:
    """Over an in-memory link a Foxglove client hears serverInfo naming the graph; a frame that
    is no JSON and a subscribe to an unknown channel each get an error status naming what
    was wrong, and the session goes on serving."""
    async with open_foxglove() as (_session, link, graph):
        info = await link.next_op()
        assert info["op"] == "serverInfo" and f"({graph.name})" in info["name"], info
        link.feed("{no json")
        link.feed({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": 77}]})
        bad = await _next_status(link)
        assert bad["level"] == 2 and "JSON" in bad["message"], bad
        unknown = await _next_status(link)
        assert unknown["level"] == 2 and "no channel 77" in unknown["message"], unknown


async def _next_status(link: Client) -> Any:
    """The next ``status`` op the session sent (the lists it sends first are skipped)."""
    while (op := await link.next_op())["op"] != "status":
        pass
    return op
