"""Plain-HTTP routes on the bridge's port: health, readiness, assets, and who sees what."""

from __future__ import annotations

from typing import Any

from bridge_server.http.web import Access, visible
from tests.helpers import BridgeProcess, open_wire
from tests.ops.support import aget


async def test_health_and_readiness(bridge: BridgeProcess) -> None:
    """/healthz and /readyz answer 200 on a running bridge, naming the worker."""
    for path, body in (("/healthz", b"ok\n"), ("/readyz", b"ready\n")):
        code, headers, got = await aget(f"http://127.0.0.1:{bridge.port}{path}")
        assert (code, got) == (200, body), path
        assert headers["x-bridge-worker"] == "0"


async def test_page_and_assets_are_served_by_the_bridge(bridge: BridgeProcess) -> None:
    """GET / is the status page; its CSS and JS come from the bridge itself (no CDN)."""
    code, headers, page = await aget(f"http://127.0.0.1:{bridge.port}/")
    assert code == 200 and headers["content-type"].startswith("text/html")
    text = page.decode()
    assert 'name="viewport"' in text
    assert "http://" not in text and "https://" not in text  # nothing external
    for asset, ctype in (("/static/app.js", "text/javascript"), ("/static/style.css", "text/css")):
        code, headers, body = await aget(f"http://127.0.0.1:{bridge.port}{asset}")
        assert code == 200 and headers["content-type"].startswith(ctype), asset
        body = body.replace(b'"http://www.w3.org/2000/svg"', b"")  # a name, not a fetch
        assert b"http://" not in body and b"https://" not in body and b"@import" not in body
    code, _, _ = await aget(f"http://127.0.0.1:{bridge.port}/static/../server.py")
    assert code != 200


async def test_websocket_clients_still_connect_on_any_path(bridge: BridgeProcess) -> None:
    """Upgrade requests pass the plain routes untouched; the handshake names the worker."""
    ws = await open_wire(bridge.url + "/")
    try:
        assert ws.ws.response is not None
        assert ws.ws.response.headers["X-Bridge-Worker"] == "0"
        await ws.send({"op": "call_service", "service": "/rosapi/get_ros_version", "id": "v"})
        await ws.expect(op="service_response", id="v", result=True)
    finally:
        await ws.close()


class _OnlyPublic(Access):
    """A viewer role that may see names under /public only, and no client but 0-1."""

    def may_see(self, principal: Any, kind: str, name: str) -> bool:
        if kind in ("topic", "service", "action"):
            return name.startswith("/public")
        if kind == "client":
            return name == "0-1"
        return True


def test_status_is_filtered_for_the_viewer() -> None:
    """visible() leaves out every topic, service, action and client the viewer may not see."""
    status = {
        "topics": {"/public/a": {}, "/secret/b": {}},
        "services": [{"name": "/public/s"}, {"name": "/secret/s"}],
        "actions": [{"name": "/secret/act"}],
        "service_calls": {"/public/s": {}, "/secret/s": {}},
        "action_goals": {},
        "clients": [
            {"id": "0-1", "subscriptions": [{"topic": "/public/a"}, {"topic": "/secret/b"}],
             "publishes": ["/secret/b"], "serves": ["/public/s", "/secret/s"]},
            {"id": "0-2", "subscriptions": [], "publishes": [], "serves": []},
        ],
    }
    shown = visible(status, "viewer", _OnlyPublic())
    assert list(shown["topics"]) == ["/public/a"]
    assert shown["services"] == [{"name": "/public/s"}]
    assert shown["actions"] == []
    assert list(shown["service_calls"]) == ["/public/s"]
    assert [c["id"] for c in shown["clients"]] == ["0-1"]
    client = shown["clients"][0]
    assert client["subscriptions"] == [{"topic": "/public/a"}]
    assert client["publishes"] == [] and client["serves"] == ["/public/s"]
    assert visible(status, None, Access()) == status  # the default: everything
