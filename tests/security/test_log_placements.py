"""Tokens in unusual placements never reach the bridge's DEBUG log (issue 53, finding 12):
in the URL fragment (``GET /#token=``), as a path segment, in a cookie, and on the second
line of a folded ``Authorization`` header (which websockets quotes in the traceback of the
request it refuses). Each is sent over a raw socket to a real bridge logging at DEBUG."""

from __future__ import annotations

import asyncio
import base64
import os
from collections.abc import Callable

import pytest

from rosbridge_core.security import redact
from tests.helpers import BridgeProcess
from tests.security.support import AuthFile
from tests.security.test_log_secrets import assert_nowhere


def _request(target: str, *headers: str) -> bytes:
    """A websocket handshake request for ``target`` with extra header lines."""
    key = base64.b64encode(os.urandom(16)).decode()
    lines = [f"GET {target} HTTP/1.1", "Host: 127.0.0.1", "Upgrade: websocket",
             "Connection: Upgrade", f"Sec-WebSocket-Key: {key}", "Sec-WebSocket-Version: 13",
             *headers, "", ""]
    return "\r\n".join(lines).encode()


PLACEMENTS: dict[str, tuple[str, Callable[[str], bytes], str]] = {
    # placement: (role whose token it is, the request, what the bridge logs once it is read)
    "fragment": ("viewer", lambda t: _request(f"/#token={t}"), r"> HTTP/1\.1 \d+"),
    "path": ("tester", lambda t: _request(f"/{t}"), r"> HTTP/1\.1 \d+"),
    "robot-path": ("admin", lambda t: _request(f"/robots/{t}/readyz"), r"> HTTP/1\.1 \d+"),
    "cookie": ("narrow", lambda t: _request("/", f"Cookie: theme=dark; token={t}"),
               r"> HTTP/1\.1 \d+"),
    "folded": ("prober", lambda t: _request("/", "Authorization: Bearer", f" {t}"),
               r"invalid HTTP header line"),
}


@pytest.mark.parametrize("placement", list(PLACEMENTS))
async def test_a_token_in_an_unusual_placement_never_reaches_the_debug_log(
    debug_bridge: BridgeProcess, auth: AuthFile, placement: str
) -> None:
    """The request is read and logged at DEBUG (the line that shows it was is awaited), and
    no 8-character piece of the token is anywhere in the log."""
    role, request, logged = PLACEMENTS[placement]
    token = auth.tokens[role]
    start = len(debug_bridge.lines)
    reader, writer = await asyncio.open_connection("127.0.0.1", debug_bridge.port)
    writer.write(request(token))
    await writer.drain()
    async with asyncio.timeout(10):
        if placement == "folded":
            await reader.read()  # refused as no valid request: the bridge closes the socket
        else:
            await reader.readuntil(b"\r\n\r\n")  # the bridge's answer
    debug_bridge.wait_for_line(logged, start=start)
    writer.close()
    log = "\n".join(debug_bridge.lines[start:])
    assert_nowhere(token, log)
    assert "<redacted>" in log  # the placement was logged, scrubbed


@pytest.mark.parametrize(("line", "kept"), [
    ("< GET /robots/robot1/readyz HTTP/1.1", "< GET /robots/robot1/readyz HTTP/1.1"),
    ("< GET /static/roslib.min.js HTTP/1.1", "< GET /static/roslib.min.js HTTP/1.1"),
    ("< GET /robots/robot-warehouse-east/status.json HTTP/1.1",
     "< GET /robots/robot-warehouse-east/status.json HTTP/1.1"),
    ("< GET /robots/r1?x=1#Zq3vLr8TnW2xKp5sYb7dHc HTTP/1.1", "< GET /robots/r1?x=1#<redacted> HTTP/1.1"),
], ids=["robot", "static", "long-name", "bare-fragment"])
def test_request_lines_keep_what_is_no_token(line: str, kept: str) -> None:
    """Short path segments and long ones of one kind of character (a robot's name) stay
    readable; a URL fragment goes whatever it holds."""
    assert redact(line) == kept
