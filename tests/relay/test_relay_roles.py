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

from bridge_server.security import SecurityConfig
from bridge_server.security.auth import hash_token, new_token
from bridge_server.server import BridgeConfig
from bridge_server.zenoh.link import ZenohOptions
from bridge_server.zenoh.relay import Relay
from tests.helpers import open_wire
from tests.relay.support import free_port, robot_reachable, start_robot

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
    tokens = {role: new_token() for role in ("robot1_viewer", "fleet_viewer")}
    auth = tmp_path / "auth.toml"
    auth.write_text(ROLES + "".join(
        f'\n[principals.{role}_user]\nrole = "{role}"\ntoken_hash = "{hash_token(token)}"\n'
        for role, token in tokens.items()))
    router = f"tcp/127.0.0.1:{free_port()}"
    relay = Relay(BridgeConfig(port=0, node_name="relay",
                               security=SecurityConfig(auth_file=str(auth))),
                  ZenohOptions(listen=[router]))
    await relay.start()
    robots = [await start_robot(router, robot=name) for name in ("robot1", "robot2")]
    try:
        for name in ("robot1", "robot2"):
            await robot_reachable(relay, name)
        yield relay, tokens
    finally:
        await relay.close()
        for bridge, exporter in robots:
            await exporter.close()
            await bridge.close()


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
    assert await _reaches(relay, "robot1", tokens["fleet_viewer"])
    assert await _reaches(relay, "robot2", tokens["fleet_viewer"])
