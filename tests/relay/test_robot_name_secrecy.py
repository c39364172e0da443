"""Robot names cannot be found out through a relay's pages without a token (issue 53,
finding 13): ``/robots/robot1/readyz`` answered 200 and ``/robots/robot9/readyz`` 401.

A real relay (the Zenoh router) with an auth file serves robot1, an rclpy robot dialing out
to it. Without a token, or with a wrong one, every route under a robot answers alike for
robot1 and for robot9, which no robot has: the same status, body and content type.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from bridge_server.zenoh.relay import Relay
from rosbridge_core.security.auth import FailureTracker, new_token
from tests.ops.support import aget
from tests.relay.support import ROBOT1_VIEWER, relay_with_auth

pytestmark = pytest.mark.timeout(120)

ROUTES = ("readyz", "healthz", "status.json", "metrics", "", "static/app.js", "nothing-here")
"""Routes under a robot: its bridge's own, its page and one of its files, and none."""


@pytest.fixture
async def relay(tmp_path: Path) -> AsyncIterator[tuple[Relay, dict[str, str]]]:
    """A relay with an auth file serving robot1 (opened), and a token of robot1's viewer."""
    async with relay_with_auth(tmp_path / "auth.toml", ROBOT1_VIEWER, ("robot1",)) as served:
        yield served


async def _answer(url: str) -> tuple[int, bytes, str]:
    code, headers, body = await aget(url)
    return code, body, headers.get("content-type", "")


async def test_a_robots_routes_answer_alike_known_or_not_without_a_token(
        relay: tuple[Relay, dict[str, str]]) -> None:
    """No token or a wrong one: robot1 (served) and robot9 (no such robot) get the same
    answer on every route, under /robots/ and at the top level; readyz is 401 for both."""
    served, tokens = relay
    assert "robot1" in served.robots
    # wrong tokens here earn no lock-out (429 for both alike; its own tests are elsewhere)
    served.security.failures = FailureTracker(free=10**6)
    base = f"http://127.0.0.1:{served.port}"
    wrong = f"?token={new_token()}"
    for route in ROUTES:
        for query in ("", wrong):
            for prefix in ("/robots/", "/"):
                known = await _answer(f"{base}{prefix}robot1/{route}{query}")
                unknown = await _answer(f"{base}{prefix}robot9/{route}{query}")
                assert known == unknown, (prefix, route, query, known[:2], unknown[:2])
    code, body, _ = await _answer(f"{base}/robots/robot1/readyz")
    assert code == 401 and b"authentication required" in body, (code, body)
    # the page and its files hold no data: served alike
    assert (await _answer(f"{base}/robots/robot9/static/app.js"))[0] == 200

    # a token that reaches them still tells them apart: that viewer may know
    viewer = f"?token={tokens['robot1_viewer']}"
    assert (await _answer(f"{base}/robots/robot1/readyz{viewer}"))[:2] == (200, b"ready\n")
    code, body, _ = await _answer(f"{base}/robots/robot9/readyz{viewer}")
    assert code == 403, (code, body)  # robot9 is not among the role's robots
