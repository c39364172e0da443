"""The plain-HTTP routes (status page, /status.json, /metrics) under an auth file."""

from __future__ import annotations

import json
from typing import Any

import pytest
from websockets.exceptions import InvalidStatus

from tests.helpers import BridgeProcess, roundtrip
from tests.ops.support import aget
from tests.security.support import AuthFile, wire


async def test_routes_need_a_token_and_introspection(auth_bridge: BridgeProcess, auth: AuthFile) -> None:
    """Without a token /metrics and /status.json are 401; a role without introspection gets 403."""
    base = f"http://127.0.0.1:{auth_bridge.port}"
    for route in ("/metrics", "/status.json"):
        code, _, body = await aget(base + route)
        assert code == 401 and b"authentication" in body
    code, _, body = await aget(f"{base}/metrics?token=wrong")
    assert code == 401 and b"wrong" not in body
    code, _, _ = await aget(f"{base}/metrics?token={auth.tokens['nothing']}")
    assert code == 403
    code, _, _ = await aget(f"{base}/metrics?token={auth.tokens['viewer']}")
    assert code == 200
    code, _, _ = await aget(base + "/healthz")  # liveness probes carry no token
    assert code == 200


async def test_status_lists_only_what_the_role_may_see(
    auth_bridge: BridgeProcess, auth: AuthFile, topic: str
) -> None:
    """/status.json for a narrow role leaves out topics its introspection patterns do not match."""
    seen, hidden = "/seen" + topic.replace("/", "_"), "/hidden" + topic.replace("/", "_")
    admin = await wire(auth_bridge.url, auth.tokens["admin"])
    for name in (seen, hidden):
        await admin.send({"op": "subscribe", "topic": name, "type": "std_msgs/msg/String"})
    await roundtrip(admin)
    base = f"http://127.0.0.1:{auth_bridge.port}/status.json?token="
    code, _, body = await aget(base + auth.tokens["admin"])
    assert code == 200 and {seen, hidden} <= set(json.loads(body)["topics"])
    code, _, body = await aget(base + auth.tokens["narrow"])
    assert code == 200
    topics = set(json.loads(body)["topics"])
    assert seen in topics and hidden not in topics
    await admin.close()


async def test_wrong_tokens_on_routes_count_toward_the_lock_out(make_bridge: Any, auth: AuthFile) -> None:
    """Wrong tokens on /metrics lock the address out: then /metrics and websockets get 429."""
    bridge = make_bridge("--auth-file", str(auth.path))
    base = f"http://127.0.0.1:{bridge.port}"
    for _ in range(5):
        code, _, _ = await aget(f"{base}/metrics?token=guess")
        assert code == 401
    code, headers, body = await aget(f"{base}/metrics?token={auth.tokens['admin']}")
    assert code == 429 and b"too many failed authentication attempts" in body
    assert int(headers["retry-after"]) >= 1
    with pytest.raises(InvalidStatus) as info:
        await wire(bridge.url, auth.tokens["admin"])
    assert info.value.response.status_code == 429
