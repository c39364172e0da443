"""No secret reaches the bridge's log, at DEBUG too (where websockets logs each request line
and header): query tokens however the key is spelled, Authorization values of any scheme,
session tokens, and a refused request line quoted in a traceback."""

from __future__ import annotations

import asyncio
import logging
import re
import sys

import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import InvalidStatus

from rosbridge_core.protocol.ops import RECEIVED_HEADER, SESSION_HEADER
from rosbridge_core.security import redact
from tests.helpers import BridgeProcess, WireClient, free_port, open_wire, ros_env, roundtrip
from tests.relay.procs import Proc
from tests.security.support import AuthFile, wire


def pieces(secret: str, size: int = 8) -> list[str]:
    """Every ``size``-character slice of ``secret``."""
    return [secret[i:i + size] for i in range(len(secret) - size + 1)]


def assert_nowhere(secret: str, text: str) -> None:
    """No 8-character piece of ``secret`` is in ``text``."""
    leaked = [p for p in pieces(secret) if p in text]
    assert not leaked, f"{len(leaked)} pieces of a secret in the log, e.g. {leaked[0]!r}"


async def test_query_tokens_in_any_spelling_never_reach_the_log(
    debug_bridge: BridgeProcess, auth: AuthFile
) -> None:
    """``?%74oken=`` (accepted: the key is decoded) and ``&token=`` after another parameter
    open sessions, and no piece of either token is in the DEBUG log."""
    encoded, later = auth.tokens["viewer"], auth.tokens["tester"]
    start = len(debug_bridge.lines)
    for url in (f"{debug_bridge.url}/?%74oken={encoded}",
                f"{debug_bridge.url}/?robot=r1&token={later}"):
        client = await open_wire(url, max_size=2**20)
        await roundtrip(client)
        await client.close()
    log = "\n".join(debug_bridge.lines[start:])
    assert "%74oken=<redacted>" in log and "&token=<redacted>" in log  # logged, scrubbed
    assert "authenticated as viewer_user" in log and "authenticated as tester_user" in log
    for token in (encoded, later):
        assert_nowhere(token, log)


async def test_authorization_values_of_any_scheme_never_reach_the_log(
    debug_bridge: BridgeProcess, auth: AuthFile
) -> None:
    """A token under a scheme other than Bearer is refused (401) and not logged, and neither
    is a Bearer token that was accepted."""
    refused, accepted = auth.tokens["nothing"], auth.tokens["narrow"]
    start = len(debug_bridge.lines)
    with pytest.raises(InvalidStatus) as info:
        await connect(debug_bridge.url, additional_headers={"Authorization": f"Token {refused}"},
                      open_timeout=10)
    assert info.value.response.status_code == 401
    client = await wire(debug_bridge.url, accepted)
    await roundtrip(client)
    await client.close()
    debug_bridge.wait_for_line("wrong token in the Authorization header", start=start)
    log = "\n".join(debug_bridge.lines[start:])
    assert "< Authorization: <redacted>" in log
    assert_nowhere(refused, log)
    assert_nowhere(accepted, log)


async def test_session_tokens_never_reach_the_log(
    debug_bridge: BridgeProcess, auth: AuthFile
) -> None:
    """The session token the bridge hands out, and the one a client resumes with, are in
    neither direction's DEBUG header lines."""
    token = auth.tokens["admin"]
    start = len(debug_bridge.lines)
    headers = {"Authorization": f"Bearer {token}", SESSION_HEADER: "new"}
    first = await connect(debug_bridge.url, additional_headers=headers, open_timeout=10)
    assert first.response is not None
    session = first.response.headers[SESSION_HEADER]
    assert len(session) >= 16
    await roundtrip(WireClient(first))
    first.transport.abort()  # the link drops: the session is kept for a resume
    debug_bridge.wait_for_line("its session is kept", start=start)
    headers.update({SESSION_HEADER: session, RECEIVED_HEADER: "1"})
    again = await connect(debug_bridge.url, additional_headers=headers, open_timeout=10)
    assert again.response is not None and RECEIVED_HEADER in again.response.headers
    await roundtrip(WireClient(again), id="after")
    await again.close()
    debug_bridge.wait_for_line("resumed its session", start=start)
    log = "\n".join(debug_bridge.lines[start:])
    assert f"> {SESSION_HEADER}: <redacted>" in log and f"< {SESSION_HEADER}: <redacted>" in log
    assert_nowhere(session, log)
    assert_nowhere(token, log)


async def test_a_refused_request_line_is_not_logged_with_its_token(
    debug_bridge: BridgeProcess, auth: AuthFile
) -> None:
    """websockets refuses an HTTP/2.0 request quoting its request line in the exception it
    logs with a traceback; the token in that line is scrubbed from the traceback too."""
    token = auth.tokens["prober"]
    start = len(debug_bridge.lines)
    reader, writer = await asyncio.open_connection("127.0.0.1", debug_bridge.port)
    writer.write(f"GET /?token={token} HTTP/2.0\r\nHost: x\r\n\r\n".encode())
    await writer.drain()
    async with asyncio.timeout(10):
        await reader.read()  # the bridge answers and closes
    writer.close()
    line = debug_bridge.wait_for_line("unsupported protocol", start=start)
    assert "token=<redacted>" in line
    assert_nowhere(token, "\n".join(debug_bridge.lines[start:]))


async def test_the_relay_logs_no_secret_either(auth: AuthFile) -> None:
    """roslibpy-lite-relay at DEBUG (the same log filter): a percent-encoded query token, a
    token after another parameter, a non-Bearer Authorization and a session token, each sent
    to it, are nowhere in its log."""
    relay = Proc([sys.executable, "-m", "bridge_server.zenoh.relay", "--port", "0",
                  "--zenoh-listen", f"tcp/127.0.0.1:{free_port()}", "--auth-file",
                  str(auth.path), "--log-level", "DEBUG"], ros_env())
    try:
        ready = re.compile(r"relay listening on ws://127\.0\.0\.1:(\d+)")
        port = int((await asyncio.to_thread(relay.wait_for, ready)).group(1))
        base = f"ws://127.0.0.1:{port}/robot1"
        secrets = {"query": auth.tokens["viewer"], "later": auth.tokens["tester"],
                   "scheme": auth.tokens["nothing"], "session": "Zq3vLr8TnW2xKp5sYb7dHc"}
        attempts = [
            (f"{base}/?%74oken={secrets['query']}", {}),
            (f"{base}/?x=1&token={secrets['later']}", {}),
            (base, {"Authorization": f"Token {secrets['scheme']}"}),
            (base, {"Authorization": f"Bearer {secrets['later']}",
                    SESSION_HEADER: secrets["session"], RECEIVED_HEADER: "0"}),
        ]
        for url, headers in attempts:
            with pytest.raises(InvalidStatus):  # no robot1 on this relay's Zenoh (or 401)
                await connect(url, additional_headers=headers, open_timeout=10)

        def answered() -> bool:  # the relay has logged all four handshakes, to the end
            return sum("HTTP response sent" in line for line in relay.lines) >= len(attempts)

        with relay.seen:
            assert relay.seen.wait_for(answered, 10), "\n".join(relay.lines)
        log = "\n".join(relay.lines)
        assert "%74oken=<redacted>" in log and f"< {SESSION_HEADER}: <redacted>" in log
        for secret in secrets.values():
            assert_nowhere(secret, log)
    finally:
        relay.stop()


SECRET = "SECRET-0123456789abcdef"


@pytest.mark.parametrize(("url", "secret"), [
    (f"GET /?robot=r1&token={SECRET} HTTP/1.1", SECRET),
    (f"GET /?a=1&b=2&%74oken={SECRET}&c=3 HTTP/1.1", SECRET),
    (f"GET /?x=%26&TOKEN={SECRET} HTTP/1.1", SECRET),
    ("GET /?a=1&token=SECRET;0123'456789\tabcdef HTTP/1.1", "SECRET;0123'456789\tabcdef"),
], ids=["second", "encoded-third", "upper-case", "semicolon-quote-tab"])
def test_redact_finds_a_query_token_in_any_position(url: str, secret: str) -> None:
    """A token parameter that is not first in the query is redacted, its whole value as the
    bridge reads it (to the next ``&``)."""
    clean = redact(url)
    assert_nowhere(secret, clean)
    assert clean.endswith("HTTP/1.1") and "=<redacted>" in clean


async def test_our_client_logs_and_errors_hold_no_secret(
    debug_bridge: BridgeProcess, auth: AuthFile, caplog: pytest.LogCaptureFixture
) -> None:
    """roslibpy_lite at DEBUG (websockets' handshake lines of its connections included): a
    token given as ``token=``, one in the URL's query and the session token appear in no log
    line, and a refused token's error text shows the URL with ``token=***``."""
    import roslibpy_lite
    from roslibpy_lite.exceptions import NotAuthenticated

    caplog.set_level(logging.DEBUG)
    given, in_query, wrong = auth.tokens["viewer"], auth.tokens["tester"], auth.tokens["blind"]
    async with roslibpy_lite.connect(debug_bridge.url, token=given) as ros:
        session = ros._ws.session
        assert session is not None and session.token
        assert await ros.graph.topics() is not None
    async with roslibpy_lite.connect(f"{debug_bridge.url}/?robot=r1&token={in_query}") as ros:
        assert ros.url.endswith("/?robot=r1&token=***")  # connected: the token was taken
    with pytest.raises(NotAuthenticated) as refused:
        await roslibpy_lite.connect(f"{debug_bridge.url}/?%74oken={wrong[:-2]}xx",
                                    open_timeout=10)
    assert "?%74oken=***" in str(refused.value)
    log = caplog.text
    # blanked by the client's own filter (***), or again by the bridge's log redaction where
    # a test before this one installed it in this process (<redacted>)
    assert re.search(r"> GET /\?robot=r1&token=(\*\*\*|<redacted>) HTTP/1\.1", log), log
    assert re.search(r"> Authorization: (\*\*\*|<redacted>)", log), log
    record = logging.LogRecord("roslibpy_lite.websockets", logging.DEBUG, __file__, 0,
                               "> GET %s HTTP/1.1", (f"/?a=1&%74oken={wrong}",), None)
    header = logging.LogRecord("roslibpy_lite.websockets", logging.DEBUG, __file__, 0,
                               "> %s: %s", ("Authorization", f"Bearer {given}"), None)
    for filtered in (record, header):  # the client's filter on its own
        assert logging.getLogger(filtered.name).filter(filtered)
    assert record.getMessage() == "> GET /?a=1&%74oken=*** HTTP/1.1"
    assert header.getMessage() == "> Authorization: ***"
    for secret in (given, in_query, wrong, session.token):
        assert_nowhere(secret, log)
        assert_nowhere(secret, str(refused.value))
