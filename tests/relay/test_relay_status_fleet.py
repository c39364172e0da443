"""A relay's ``/status.json`` with a fleet on its network (issue 49): one page is one pass.

The page lists every robot on the relay's Zenoh network with its rates. Each robot's entry
took every robot's rates again (a pass over all of them per robot): with 500 robots a page
took 1-3 s of the relay's loop, and the fleet benchmark's read of a 1,000-robot page ended
short. Here a relay's routes (:class:`~bridge_server.zenoh.relay_web.RelayWeb`) answer
over a stand-in for the relay that names 1,000 robots on the network.
"""

from __future__ import annotations

import json
from typing import Any

import pytest
from websockets.datastructures import Headers
from websockets.http11 import Request

from bridge_server.front.handshake import Security
from bridge_server.http.rates import Window
from bridge_server.http.web_access import WebAccess
from bridge_server.zenoh.forget import Forgetter
from bridge_server.zenoh.relay_web import RelayWeb
from rosbridge_core.security.options import SecurityConfig

ROBOTS = 1000


class _Fleet:
    """The relay as its routes see it: nothing opened, :data:`ROBOTS` robots on Zenoh."""

    relay_id = "relay-status"
    robots: dict[str, Any] = {}
    refused: dict[str, int] = {}
    names_refused: dict[str, dict[str, Any]] = {}
    forgetter = Forgetter(robots)

    async def robot(self, name: str) -> None:
        """No robot is opened here."""

    async def on_network(self) -> set[str]:
        """The fleet's robots, all present."""
        return {f"sim-{i}" for i in range(ROBOTS)}

    def trouble(self) -> None:
        """The relay serves."""

    def robots_refused(self) -> dict[str, Any]:
        """Nobody refused."""
        return {}


async def test_status_page_of_a_fleet_takes_the_rates_once(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Three reads of ``/status.json`` with 1,000 robots on the network list them all, with
    their rates from the second read on, and take the rates' window once a page (it was
    once a robot)."""
    passes: list[int] = []
    rates = Window.rates

    def counted(self: Window) -> dict[str, tuple[float, ...]]:
        passes.append(1)
        return rates(self)

    monkeypatch.setattr(Window, "rates", counted)
    web = RelayWeb(_Fleet(), WebAccess(Security(SecurityConfig())))
    bodies = []
    for _ in range(3):
        reply = await web.answer(Request("/status.json", Headers()), "127.0.0.1")
        assert reply is not None and reply.status == 200
        bodies.append(reply.body)
    page = json.loads(bodies[-1])
    assert len(page["robots"]) == ROBOTS
    assert all(r["present"] and not r["served"] for r in page["robots"])
    assert all(set(r["rates"]) >= {"messages_from_robot_per_s"} for r in page["robots"])
    assert len(passes) == 3, f"{len(passes)} passes over the robots' rates for 3 pages"
