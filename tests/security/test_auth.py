"""Authentication: every way a token can arrive, refusals, the lock-out, and no token in logs."""

from __future__ import annotations

import logging
import subprocess
import sys
from pathlib import Path
from typing import Any

import cbor2
import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed, InvalidStatus

from bridge_server.front.handshake import Security
from rosbridge_core.security import SecurityConfig, redact
from rosbridge_core.security.auth import AuthFileError, FailureTracker, load_auth_file, new_token
from tests.helpers import ROOT, BridgeProcess, ros_env, roundtrip
from tests.ops.support import aget
from tests.security.support import AuthFile, wire


async def test_bearer_header_authenticates(auth_bridge: BridgeProcess, auth: AuthFile) -> None:
    """A valid token in an Authorization: Bearer header opens a working session."""
    ws = await wire(auth_bridge.url, auth.tokens["viewer"])
    await roundtrip(ws)
    await ws.close()


async def test_query_token_authenticates(auth_bridge: BridgeProcess, auth: AuthFile) -> None:
    """A valid token in the ?token= query parameter (what browsers can send) works."""
    ws = await wire(f"{auth_bridge.url}/?token={auth.tokens['viewer']}")
    await roundtrip(ws)
    await ws.close()


async def test_auth_op_authenticates(auth_bridge: BridgeProcess, auth: AuthFile) -> None:
    """An auth op as the first message (roslib's authenticate()) with the token as mac works."""
    ws = await wire(auth_bridge.url)
    await ws.send({"op": "auth", "mac": auth.tokens["viewer"], "client": "c", "dest": "d",
                   "rand": "r", "t": 0, "level": "user", "end": 0})
    await roundtrip(ws)
    await ws.close()


@pytest.mark.parametrize("where", ["header", "query"])
async def test_wrong_token_is_http_401(auth_bridge: BridgeProcess, where: str) -> None:
    """A wrong token in the header or the query is refused at the handshake with HTTP 401."""
    url, headers = auth_bridge.url, {}
    if where == "header":
        headers["Authorization"] = "Bearer not-a-valid-token"
    else:
        url += "/?token=not-a-valid-token"
    with pytest.raises(InvalidStatus) as info:
        await connect(url, additional_headers=headers, open_timeout=10)
    response = info.value.response
    assert response.status_code == 401
    assert b"authentication failed" in response.body and b"not-a-valid" not in response.body
    assert response.headers["WWW-Authenticate"].startswith("Bearer")


async def test_wrong_auth_op_closes_with_1008(auth_bridge: BridgeProcess) -> None:
    """A failed auth op closes the connection with code 1008 (policy violation)."""
    ws = await wire(auth_bridge.url)
    await ws.send({"op": "auth", "mac": "wrong-token"})
    with pytest.raises(ConnectionClosed) as info:
        await ws.recv()
    assert info.value.rcvd is not None and info.value.rcvd.code == 1008
    assert "authentication failed" in info.value.rcvd.reason


async def test_ops_before_auth_are_refused(
    auth_bridge: BridgeProcess, auth: AuthFile, ros_node: Any, topic: str
) -> None:
    """Without a token, an op other than auth closes the connection (1008) and is not carried out."""
    ws = await wire(auth_bridge.url)
    await ws.send({"op": "advertise_service", "service": topic, "type": "std_srvs/srv/SetBool"})
    with pytest.raises(ConnectionClosed) as info:
        await ws.recv()
    assert info.value.rcvd is not None and info.value.rcvd.code == 1008
    assert "authentication required" in info.value.rcvd.reason
    admin = await wire(auth_bridge.url, auth.tokens["admin"])
    await admin.send({"op": "call_service", "service": "/rosapi/services", "id": "s"})
    listed = await admin.expect(op="service_response", id="s")
    assert topic not in listed["values"]["services"]
    await admin.close()


async def test_no_token_times_out(make_bridge: Any, auth: AuthFile) -> None:
    """A connection that never authenticates is closed (1008) after the handshake timeout."""
    bridge = make_bridge("--auth-file", str(auth.path), "--handshake-timeout", "1")
    ws = await wire(bridge.url)
    with pytest.raises(ConnectionClosed) as info:
        await ws.recv(timeout=20)
    assert info.value.rcvd is not None and info.value.rcvd.code == 1008
    assert "authentication required" in info.value.rcvd.reason


async def test_repeated_failures_lock_the_address_out(make_bridge: Any, auth: AuthFile) -> None:
    """After 5 failures from one address even a valid token gets 429 with Retry-After."""
    bridge = make_bridge("--auth-file", str(auth.path))
    for _ in range(5):
        with pytest.raises(InvalidStatus) as info:
            await connect(f"{bridge.url}/?token=guess", open_timeout=10)
        assert info.value.response.status_code == 401
    with pytest.raises(InvalidStatus) as info:
        await wire(bridge.url, auth.tokens["admin"])
    assert info.value.response.status_code == 429
    assert int(info.value.response.headers["Retry-After"]) >= 1
    assert b"too many failed authentication attempts" in info.value.response.body


def test_a_new_token_never_reads_as_an_option() -> None:
    """Tokens go on command lines (``--token TOKEN``): none starts with '-' (one in 64 of
    URL-safe base64 would, so 2,000 of them all but surely meet it)."""
    tokens = [new_token() for _ in range(2000)]
    assert not [t for t in tokens if t.startswith("-")]
    assert len(set(tokens)) == 2000 and all(len(t) == 43 for t in tokens)


def test_failure_tracker_backs_off_and_forgets() -> None:
    """The lock-out grows with each failure past the free ones; a success does not reset it."""
    tracker = FailureTracker(free=2, max_lockout=60)
    tracker.failed("a")
    assert tracker.locked_for("a") == 0
    tracker.failed("a")
    first = tracker.locked_for("a")
    tracker.failed("a")
    assert 0 < first <= 1 < tracker.locked_for("a") <= 2
    assert tracker.locked_for("b") == 0
    tracker.succeeded("a")  # interleaved valid logins must not reset a guesser's count
    assert tracker.locked_for("a") > 0
    tracker.failed("a")
    assert tracker.locked_for("a") > 2


async def test_tokens_never_reach_the_log(make_bridge: Any, auth: AuthFile) -> None:
    """With DEBUG logging, no token (valid or wrong, header, query or auth op) is in the log."""
    bridge = make_bridge("--auth-file", str(auth.path), "--log-level", "DEBUG")
    wrong = "Wq7zXk2Vb9Lr4Tn8Jd1Hs6"  # random-looking: no 6 characters of it occur by chance
    good = auth.tokens["viewer"]
    ws = await wire(bridge.url, good)
    await roundtrip(ws)
    await ws.close()
    ws = await wire(f"{bridge.url}/?token={good}")
    await roundtrip(ws)
    await ws.close()
    ws = await wire(bridge.url)
    await ws.send({"op": "auth", "mac": good})
    await roundtrip(ws)
    await ws.close()
    for url in (f"{bridge.url}/?token={wrong}",):
        with pytest.raises(InvalidStatus):
            await connect(url, open_timeout=10)
    ws = await wire(bridge.url)
    await ws.send({"op": "auth", "mac": wrong})
    with pytest.raises(ConnectionClosed):
        await ws.recv()
    bridge.wait_for_line("auth op from .* wrong token")
    ws = await wire(bridge.url)
    await ws.send_raw(cbor2.dumps({"op": "auth", "mac": good}))  # logged as hex at DEBUG
    await roundtrip(ws)
    await ws.close()
    code, _, _ = await aget(f"http://127.0.0.1:{bridge.port}/metrics?token={wrong}")
    assert code == 401
    bridge.wait_for_line("plain-HTTP request .* wrong token")
    log = bridge.log()
    assert "authenticated as viewer_user" in log
    flat = log.replace(" ", "")
    for token in (good, wrong):
        for i in range(len(token) - 5):  # no part of it, as text or as hex
            part = token[i:i + 6]
            assert part not in log and part.encode().hex() not in flat


def test_redact_scrubs_every_carrier() -> None:
    """The log filter hides bearer headers, query tokens, auth-op macs and received frames."""
    text = "Authorization: Bearer abc123\nGET /?token=xyz&x=1 {'mac': 'm1'} {\"mac\": \"m2\"}"
    clean = redact(text)
    for secret in ("abc123", "xyz", "m1", "m2"):
        assert secret not in clean
    assert "x=1" in clean
    frame = redact("< BINARY a2 62 6f 70 ... 42 6b 6d 49 [58 bytes]")
    assert frame == "< BINARY <redacted> [58 bytes]"


def test_add_principal_prints_a_token_once_and_stores_a_hash(tmp_path: Path) -> None:
    """The helper command adds a principal; the file holds only a hash that verifies the token."""
    path = tmp_path / "auth.toml"
    out = subprocess.run(
        [sys.executable, "-m", "bridge_server", "add-principal", "alice", "--role", "viewer",
         "--auth-file", str(path)],
        cwd=ROOT, env=ros_env(), capture_output=True, text=True, timeout=60, check=True,
    )
    token = out.stdout.strip()
    assert len(token) >= 40 and token not in path.read_text()
    config = load_auth_file(path)
    principal = config.verify(token)
    assert principal is not None and principal.name == "alice" and principal.role.name == "viewer"
    assert config.verify(token + "x") is None
    again = subprocess.run(
        [sys.executable, "-m", "rosbridge_core.security.auth", "alice", "--role", "viewer",
         "--auth-file", str(path)],
        cwd=ROOT, env=ros_env(), capture_output=True, text=True, timeout=60,
    )
    assert again.returncode == 1 and "exists already" in again.stderr


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[principals.a]\nrole = 'x'\ntoken_hash = 'sha256$00$00'\n", "role 'x' is not defined"),
        ("[roles.r]\nfly = ['*']\n", "unknown capability 'fly'"),
        ("[roles.r]\n[principals.a]\nrole = 'r'\ntoken_hash = 'md5$1'\n", "token_hash must"),
        ("[roles.r\n", "not valid TOML"),
    ],
)
def test_bad_auth_file_names_the_problem(tmp_path: Path, text: str, message: str) -> None:
    """A malformed auth file is refused with a message naming the file and the key."""
    path = tmp_path / "auth.toml"
    path.write_text(text)
    with pytest.raises(AuthFileError, match=message) as info:
        load_auth_file(path)
    assert str(path) in str(info.value)


def test_bridge_refuses_to_start_with_a_bad_auth_file(tmp_path: Path) -> None:
    """The bridge exits 1 with one clear line when the auth file cannot be used."""
    path = tmp_path / "auth.toml"
    path.write_text("[roles.r]\nfly = ['*']\n")
    out = subprocess.run(
        [sys.executable, "-m", "bridge_server", "--port", "0", "--auth-file", str(path)],
        cwd=ROOT, env=ros_env(), capture_output=True, text=True, timeout=60,
    )
    assert out.returncode == 1
    assert "cannot start" in out.stderr and "unknown capability 'fly'" in out.stderr
    assert "Traceback" not in out.stderr


@pytest.mark.parametrize(
    ("host", "auth_file", "cert", "expected"),
    [
        ("0.0.0.0", False, False, "neither authentication"),
        ("0.0.0.0", True, False, "tokens travel in clear text"),
        ("192.168.1.5", False, True, "no --auth-file"),
        ("127.0.0.1", False, False, None),
        ("::1", False, False, None),
    ],
)
def test_startup_warning_for_exposed_ports(
    caplog: pytest.LogCaptureFixture, auth: AuthFile, host: str, auth_file: bool, cert: bool,
    expected: str | None,
) -> None:
    """Binding a non-loopback address without auth or TLS logs a loud warning; loopback does not."""
    config = SecurityConfig(auth_file=str(auth.path) if auth_file else None,
                            certfile="unused.pem" if cert else None)
    with caplog.at_level(logging.WARNING, logger="bridge_server.security"):
        Security(config).startup_warnings(host)
    if expected is None:
        assert not caplog.records
    else:
        assert len(caplog.records) == 1 and expected in caplog.records[0].getMessage()


def test_help_lists_security_options() -> None:
    """--help documents every security option."""
    out = subprocess.run(
        [sys.executable, "-m", "bridge_server", "--help"],
        cwd=ROOT, env=ros_env(), capture_output=True, text=True, timeout=60, check=True,
    ).stdout
    for option in ("--certfile", "--keyfile", "--client-ca", "--auth-file", "--allowed-origins",
                   "--max-clients", "--max-clients-per-address", "--handshake-timeout",
                   "--max-op-rate", "--max-subscriptions", "--max-publishers", "--max-services",
                   "--max-goals", "--inbound-budget", "--inbound-budget-total"):
        assert option in out


def test_example_auth_file_loads() -> None:
    """examples/auth.example.toml (the roles SECURITY.md documents) is a valid auth file."""
    config = load_auth_file(ROOT / "examples" / "auth.example.toml")
    viewer, operator, admin = (config.roles[n] for n in ("viewer", "operator", "admin"))
    assert viewer.allows("subscribe", "/camera/image") and not viewer.allows("publish", "/cmd_vel")
    assert operator.allows("publish", "/cmd_vel") and not operator.allows("publish", "/rosout")
    assert admin.allows("params", "/node:speed") and not operator.has("params")


async def test_large_frames_before_auth_close_the_connection(auth_bridge: BridgeProcess) -> None:
    """Before authenticating, a frame larger than an auth op closes the connection (1009 at its
    header: the bridge never holds it)."""
    ws = await wire(auth_bridge.url)
    await ws.send({"op": "fragment", "id": "f", "data": "x" * 100_000, "num": 0, "total": 2})
    with pytest.raises(ConnectionClosed) as info:
        await ws.recv()
    assert info.value.rcvd is not None and info.value.rcvd.code == 1009
    assert "16384" in info.value.rcvd.reason


async def test_frames_up_to_the_message_size_once_an_auth_op_succeeded(
    auth_bridge: BridgeProcess, auth: AuthFile
) -> None:
    """After a successful auth op (roslib's authenticate()), a frame over the 16 KiB
    pre-authentication limit is read and answered, as with a token at the handshake."""
    ws = await wire(auth_bridge.url)
    await ws.send({"op": "auth", "mac": auth.tokens["viewer"]})
    await ws.send({"op": "call_service", "service": "/rosapi/get_ros_version", "id": "big",
                   "padding": "x" * 40_000})  # a frame of about 40 kB
    response = await ws.expect(op="service_response", id="big")
    assert response["result"] is True
    await ws.close()


async def test_fragments_before_auth_are_refused(auth_bridge: BridgeProcess) -> None:
    """Without a token, a fragment is not held for reassembly: the connection closes (1008)."""
    ws = await wire(auth_bridge.url)
    await ws.send({"op": "fragment", "id": "f", "data": '{"op": "sub', "num": 0, "total": 2})
    with pytest.raises(ConnectionClosed) as info:
        await ws.recv(timeout=20)
    assert info.value.rcvd is not None and info.value.rcvd.code == 1008
    assert "authentication required before 'fragment'" in info.value.rcvd.reason


def test_principal_repr_holds_no_token_hash(auth: AuthFile) -> None:
    """A principal's repr (in a traceback or a log line) shows neither its salt nor its digest."""
    for principal in load_auth_file(auth.path).principals:
        text = repr(principal)
        assert principal.name in text
        assert principal.digest.hex() not in text and principal.salt.hex() not in text
        assert repr(principal.digest) not in text


async def test_large_frame_before_auth_closes_at_its_header(auth_bridge: BridgeProcess) -> None:
    """Without a token, a frame header announcing 15 MiB closes the connection (1009) at once:
    the bridge does not wait for, or hold, the bytes it announced."""
    ws = await wire(auth_bridge.url)
    size = 15 << 20
    # A masked text frame header (FIN, opcode 1; 127: a 64-bit length follows), a zero mask,
    # and only the first 1,000 of the 15 MiB it announces.
    ws.ws.transport.write(b"\x81\xff" + size.to_bytes(8, "big") + b"\0\0\0\0" + b"x" * 1000)
    with pytest.raises(ConnectionClosed) as info:
        await ws.recv(timeout=20)
    assert info.value.rcvd is not None and info.value.rcvd.code == 1009
    assert f"frame with {size} bytes exceeds limit of 16384 bytes" in info.value.rcvd.reason


async def test_locked_out_address_gets_no_guess_on_open_connections(
    make_bridge: Any, auth: AuthFile
) -> None:
    """Connections opened before a lock-out cannot use auth ops to go on guessing."""
    bridge = make_bridge("--auth-file", str(auth.path))
    waiting = [await wire(bridge.url) for _ in range(6)]
    for ws in waiting[:5]:
        await ws.send({"op": "auth", "mac": "guess"})
        with pytest.raises(ConnectionClosed):
            await ws.recv(timeout=20)
    await waiting[5].send({"op": "auth", "mac": auth.tokens["admin"]})
    with pytest.raises(ConnectionClosed) as info:
        await waiting[5].recv(timeout=20)
    assert info.value.rcvd is not None and info.value.rcvd.code == 1008
    assert "too many failed authentication attempts" in info.value.rcvd.reason


def test_add_principal_refuses_a_name_toml_cannot_hold(tmp_path: Path) -> None:
    """A non-ASCII principal name is refused before anything is written; the file stays usable."""
    from rosbridge_core.security.auth import add_principal

    path = tmp_path / "auth.toml"
    add_principal(path, "alice", "viewer")
    with pytest.raises(AuthFileError, match="ASCII letters"):
        add_principal(path, "é", "viewer")
    add_principal(path, "bob", "viewer")
    assert [p.name for p in load_auth_file(path).principals] == ["alice", "bob"]


def test_failures_long_past_are_forgotten() -> None:
    """A failure long after the last one starts the count afresh instead of extending a lock-out."""
    from rosbridge_core.security import auth as auth_module

    now = [1000.0]
    tracker = FailureTracker(free=2, max_lockout=60, clock=lambda: now[0])
    for _ in range(4):
        tracker.failed("a")
    assert tracker.locked_for("a") > 0
    now[0] += auth_module.FORGET_AFTER + 1
    assert tracker.failed("a") == 1 and tracker.locked_for("a") == 0
