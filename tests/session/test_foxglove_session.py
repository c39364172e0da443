"""A Foxglove session on its ports alone: the same in-memory link and graph as a rosbridge one."""

from __future__ import annotations

from typing import Any

from tests.session.harness import Client, open_foxglove


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
