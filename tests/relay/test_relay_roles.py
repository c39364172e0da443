"""A relay's roles limited to robots (issue 26 item 4): ``robots = [...]`` in a role.

One relay (the Zenoh router) with an auth file, two robots (rclpy Graphs with their
exporters, in this process) dialing out to it: a token whose role names robot1 reaches
robot1 and is refused robot2 before the handshake; a role without ``robots`` reaches both.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from pathlib import Path

import pytest
from websockets.exceptions import InvalidStatus

from bridge_server.zenoh.relay import Relay
from tests.helpers import open_wire
from tests.relay.support import relay_with_auth

pytestmark = pytest.mark.timeout(90)

ROLES = """
[roles.robot1_viewer]
subscribe = ["*"]
robots = ["robot1"]

[roles.fleet_viewer]
subscribe = ["*"]
"""


@pytest.fixture
async def relay_with_roles(tmp_path: Path) -> AsyncIterator[tuple[Relay, dict[str, str]]]:
    """A relay with the roles above (a token each) serving robot1 and robot2."""
    async with relay_with_auth(tmp_path / "auth.toml", ROLES) as served:
        yield served


async def _reaches(relay: Relay, robot: str, token: str) -> bool:
    try:
        wire = await open_wire(f"ws://127.0.0.1:{relay.port}/{robot}?token={token}")
    except InvalidStatus as exc:
        assert exc.response.status_code == 403
        assert f"may not reach robot '{robot}'" in exc.response.body.decode()
        return False
    await wire.close()
    return True


async def test_a_role_reaches_only_its_robots(relay_with_roles: tuple[Relay, dict[str, str]]
                                              ) -> None:
    relay, tokens = relay_with_roles
    assert await _reaches(relay, "robot1", tokens["robot1_viewer"])
    assert not await _reaches(relay, "robot2", tokens["robot1_viewer"])
    # counted as the relay's refusal (roslibpy_relay_connections_refused_total{reason=...})
    assert relay.refused == {"robot_not_allowed": 1}
    assert await _reaches(relay, "robot1", tokens["fleet_viewer"])
    assert await _reaches(relay, "robot2", tokens["fleet_viewer"])
