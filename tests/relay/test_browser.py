"""Stock roslib (npm, unchanged) in a real headless Chromium, through a relay (issue 26).

The page loads roslib's own ES module build from ``tests/peers/node/node_modules`` (an
import map names its dependencies' browser builds), connects to the relay with the robot in
the URL's path, subscribes to an rclpy topic on the robot and calls its service. Debian's
chromium and chromium-driver (scripts/setup.sh installs them); under CI their absence fails.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import http.server
import json
import threading
from collections.abc import AsyncIterator, Awaitable, Callable
from typing import Any

import pytest
from std_msgs.msg import String
from std_srvs.srv import SetBool

from tests.helpers import CHROMEDRIVER, CHROMIUM, ROOT, headless_chromium
from tests.relay.support import tier

NODE_MODULES = ROOT / "tests" / "peers" / "node" / "node_modules"

pytestmark = [
    pytest.mark.timeout(120),
    pytest.mark.skipif(CHROMIUM is None or CHROMEDRIVER is None or not (NODE_MODULES / "roslib").is_dir(),
                       reason="chromium, chromium-driver and the npm peer packages are needed "
                              "(scripts/setup.sh installs them)"),
]

IMPORTS = {
    "eventemitter3": "/eventemitter3/dist/eventemitter3.esm.js",
    "uuid": "/uuid/dist/index.js",
    "bson": "/bson/lib/bson.mjs",
    "cbor2": "/cbor2/lib/index.js",
    "cbor2/": "/cbor2/lib/",
    "@cto.af/wtf8": "/@cto.af/wtf8/lib/index.js",
    "fast-png": "/fast-png/lib/index.js",
    "iobuffer": "/iobuffer/lib/iobuffer.js",
    "fflate": "/fflate/esm/browser.js",
}

PAGE = """<!doctype html><meta charset="utf-8"><title>roslib through a relay</title>
<script type="importmap">{"imports": %(imports)s}</script>
<script type="module">
import * as ROSLIB from "/roslib/dist/RosLib.js";
window.got = []; window.answer = null; window.problem = null;
const ros = new ROSLIB.Ros({url: %(url)s});
ros.on("error", (e) => { window.problem = "error: " + (e && e.message || e); });
ros.on("close", () => { window.problem = window.problem || "the connection closed"; });
ros.on("connection", () => {
  new ROSLIB.Topic({ros, name: %(topic)s, messageType: "std_msgs/msg/String"})
    .subscribe((m) => window.got.push(m.data));
  new ROSLIB.Service({ros, name: %(service)s, serviceType: "std_srvs/srv/SetBool"})
    .callService({data: true}, (r) => { window.answer = r; },
                 (e) => { window.answer = {failed: String(e)}; });
});
</script>"""


class _Files(http.server.SimpleHTTPRequestHandler):
    """node_modules as static files (JavaScript as JavaScript), and the test's page."""

    extensions_map = {".js": "text/javascript", ".mjs": "text/javascript",
                      ".json": "application/json", "": "application/octet-stream"}
    page = b""

    def do_GET(self) -> None:
        if self.path == "/page.html":
            self.send_response(200)
            self.send_header("Content-Type", "text/html; charset=utf-8")
            self.send_header("Content-Length", str(len(self.page)))
            self.end_headers()
            self.wfile.write(self.page)
            return
        super().do_GET()

    def log_message(self, *args: Any) -> None:
        pass


@contextlib.asynccontextmanager
async def roslib_in_chromium(url: str, topic: str, service: str
                             ) -> AsyncIterator[Callable[[], Awaitable[dict[str, Any]]]]:
    """Stock roslib in headless Chromium on a page that connects to ``url``, subscribes to the
    std_msgs/String ``topic`` and calls the std_srvs/SetBool ``service`` with ``data: true``;
    yields an awaitable read of the page's ``{got, answer, problem}``."""
    page = (PAGE % {"imports": json.dumps(IMPORTS), "url": json.dumps(url),
                    "topic": json.dumps(topic), "service": json.dumps(service)}).encode()
    handler = type("Files", (_Files,), {"page": page})
    server = http.server.ThreadingHTTPServer(
        ("127.0.0.1", 0), functools.partial(handler, directory=str(NODE_MODULES)))
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        with headless_chromium("relay") as driver:
            await asyncio.to_thread(driver.get,
                                    f"http://127.0.0.1:{server.server_address[1]}/page.html")

            async def read() -> dict[str, Any]:
                state: dict[str, Any] = await asyncio.to_thread(
                    driver.execute_script,
                    "return {got: window.got, answer: window.answer, problem: window.problem}")
                return state

            yield read
    finally:
        server.shutdown()
        server.server_close()


async def heard_and_answered(read: Callable[[], Awaitable[dict[str, Any]]],
                             nudge: Callable[[], object] = lambda: None,
                             timeout: float = 60.0) -> dict[str, Any]:
    """The page's state once it heard the topic and got the service's answer; ``nudge`` runs
    before each look (an rclpy publish: discovery has no event here). Fails on the page's
    error at once, and at the deadline naming what the page had."""
    deadline = asyncio.get_running_loop().time() + timeout
    while True:
        nudge()
        state = await read()
        assert state.get("problem") is None, state
        if state.get("got") and state.get("answer"):
            return state
        assert asyncio.get_running_loop().time() < deadline, state
        await asyncio.sleep(0.1)


async def test_roslib_in_a_browser_through_the_relay(ros_node: Any, topic: str) -> None:
    """roslib hears an rclpy topic on the in-process tier's robot and calls its service."""
    service = topic + "_set"
    pub = ros_node.create_publisher(String, topic, 10)

    def serve(request: Any, response: Any) -> Any:
        response.success, response.message = request.data, "from the robot"
        return response

    ros_node.create_service(SetBool, service, serve)
    async with tier() as t, roslib_in_chromium(t.url(), topic, service) as read:
        state = await heard_and_answered(read, lambda: pub.publish(String(data="to the browser")))
        assert state["got"][0] == "to the browser"
        assert state["answer"] == {"success": True, "message": "from the robot"}
