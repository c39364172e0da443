"""A relay's admission (issues 39 and 43): who makes it open a robot, and the robot limit.

One relay (the Zenoh router) with an auth file, robot1 and robot2 (rclpy Graphs with their
exporters, in this process) dialing out to it, neither opened by the relay at first:

- a role limited to robot1 (``robots = ["robot1"]``) reaches robot2 by no way of giving
  its token: ``Authorization: Bearer``, ``?token=``, the ``auth`` op after connecting
  without one, a Foxglove client with either; robot2 is never opened, and its ROS side
  never answers (``/rosapi/topics``), while the same way reaches robot1;
- a client without a token (rosbridge, Foxglove, a plain GET of the robot's page) does not
  make the relay open the robot: only an authenticated one does.
"""

from __future__ import annotations

import json
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed, InvalidStatus

from bridge_server.foxglove import SUBPROTOCOL
from bridge_server.zenoh.relay import Relay
from tests.helpers import open_wire
from tests.ops.support import aget
from tests.relay.support import ROBOT1_VIEWER, relay_with_auth

pytestmark = pytest.mark.timeout(90)

WAYS = ("header", "query", "auth_op")


@pytest.fixture
async def relay(tmp_path: Path) -> AsyncIterator[tuple[Relay, str]]:
    """A relay with an auth file (a role seeing robot1 alone) serving robot1 and robot2,
    neither opened yet; the role's token."""
    async with relay_with_auth(tmp_path / "auth.toml", ROBOT1_VIEWER,
                               open_robots=False) as (relay, tokens):
        assert relay.robots == {}
        yield relay, tokens["robot1_viewer"]


async def _topics(relay: Relay, robot: str, token: str, way: str) -> Any:
    """``/rosapi/topics`` asked of ``robot`` with ``token`` given ``way``: the answer, or
    what refused it (the handshake's HTTP status, or the close reason)."""
    url = f"ws://127.0.0.1:{relay.port}/{robot}"
    kw: dict[str, Any] = {"max_size": None, "open_timeout": 10}
    if way == "header":
        kw["additional_headers"] = {"Authorization": f"Bearer {token}"}
    elif way == "query":
        url += f"?token={token}"
    try:
        async with connect(url, **kw) as ws:
            if way == "auth_op":
                await ws.send(json.dumps({"op": "auth", "mac": token}))
            await ws.send(json.dumps({"op": "call_service", "service": "/rosapi/topics",
                                      "id": "t"}))
            try:
                return await ws.recv()
            except ConnectionClosed:
                return f"closed {ws.close_code}: {ws.close_reason}"
    except InvalidStatus as exc:
        return f"{exc.response.status_code}: {exc.response.body.decode()}"


@pytest.mark.parametrize("way", WAYS)
async def test_a_role_limited_to_robot1_reaches_robot2_by_no_way(
        relay: tuple[Relay, str], way: str) -> None:
    """robot1's role asking for robot2 with its token given ``way``: refused saying so,
    robot2 never opened and its /rosapi/topics never answered; robot1 answers the same."""
    r, token = relay
    answer = await _topics(r, "robot2", token, way)
    assert "may not reach robot 'robot2'" in answer, answer
    assert answer.startswith("403" if way != "auth_op" else "closed 1008"), answer
    assert "robot2" not in r.robots and r.refused == {"robot_not_allowed": 1}
    answer = await _topics(r, "robot1", token, way)
    assert '"service_response"' in answer, answer
    assert set(r.robots) == {"robot1"}


@pytest.mark.parametrize("way", ("header", "query"))
async def test_a_foxglove_client_of_robot1s_role_is_refused_robot2(
        relay: tuple[Relay, str], way: str) -> None:
    """A Foxglove client with robot1's role's token (``way``) asking for robot2: 403 at the
    handshake, robot2 never opened; the same client reaches robot1."""
    r, token = relay
    for robot in ("robot2", "robot1"):
        url = f"ws://127.0.0.1:{r.port}/{robot}"
        headers = {"Authorization": f"Bearer {token}"} if way == "header" else None
        url += "?token=" + token if way == "query" else ""
        try:
            async with connect(url, subprotocols=[SUBPROTOCOL],  # type: ignore[list-item]
                               additional_headers=headers, open_timeout=10) as ws:
                assert robot == "robot1" and ws.subprotocol == SUBPROTOCOL
                assert '"serverInfo"' in str(await ws.recv())
        except InvalidStatus as exc:
            assert robot == "robot2" and exc.response.status_code == 403, exc.response.body
    assert set(r.robots) == {"robot1"} and r.refused == {"robot_not_allowed": 1}


async def test_a_client_without_a_token_does_not_open_a_robot(relay: tuple[Relay, str]
                                                                ) -> None:
    """Without a token: a rosbridge client's first op other than auth closes it, a Foxglove
    client is closed, a plain GET of the robot's status is 401; robot1 is never opened. The
    auth op with the role's token then opens it and is answered."""
    r, token = relay
    base = f"ws://127.0.0.1:{r.port}/robot1"
    wire = await open_wire(base)
    assert wire.ws.response is not None
    assert wire.ws.response.headers["X-Rosbridge-Auth"] == "required"
    await wire.send({"op": "call_service", "service": "/rosapi/topics", "id": "t"})
    with pytest.raises(ConnectionClosed):
        await wire.recv()
    assert wire.ws.close_code == 1008 and "send the auth op first" in str(wire.ws.close_reason)
    async with connect(base, subprotocols=[SUBPROTOCOL],  # type: ignore[list-item]
                       open_timeout=10) as ws:
        with pytest.raises(ConnectionClosed):
            await ws.recv()
        assert ws.close_code == 1008 and "give the token" in str(ws.close_reason)
    code, _, body = await aget(f"http://127.0.0.1:{r.port}/robot1/status.json")
    assert code == 401, body
    assert r.robots == {}
    assert '"service_response"' in await _topics(r, "robot1", token, "auth_op")
    assert set(r.robots) == {"robot1"}
