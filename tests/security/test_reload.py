"""SIGHUP: the bridge reads its auth file and certificates again, without a restart."""

from __future__ import annotations

import signal
import ssl
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from websockets.exceptions import ConnectionClosed, InvalidStatus

from rosbridge_core.security.auth import (
    AuthFileError,
    add_principal,
    load_auth_file,
    remove_principal,
)
from tests.helpers import ROOT, BridgeProcess, WireClient, ros_env, roundtrip
from tests.security.support import ROLES, wire

TWIST = "geometry_msgs/msg/Twist"


@pytest.fixture
def auth_path(tmp_path: Path) -> Path:
    """An auth file with the test roles and no principals yet."""
    path = tmp_path / "auth.toml"
    path.write_text(ROLES)
    return path


@pytest.fixture
def bridges() -> Iterator[list[BridgeProcess]]:
    """Bridges a test starts; stopped afterwards."""
    started: list[BridgeProcess] = []
    yield started
    for bridge in started:
        bridge.stop()


def reload(bridge: BridgeProcess, pattern: str) -> str:
    """Send the bridge SIGHUP and wait for its log line matching ``pattern``."""
    start = len(bridge.lines)
    assert bridge.proc is not None
    bridge.proc.send_signal(signal.SIGHUP)
    return bridge.wait_for_line(pattern, start=start)


async def reload_revoking(bridge: BridgeProcess, client: WireClient, name: str) -> None:
    """SIGHUP the bridge, whose new file has 2 principals: ``client``'s session, principal
    ``name``'s, is the one closed as revoked (1008)."""
    line = reload(bridge, r"reloaded the auth file")
    assert "2 principal(s)" in line and "1 session(s) closed as revoked" in line
    with pytest.raises(ConnectionClosed) as closed:
        while True:
            await client.recv()
    assert closed.value.rcvd is not None and closed.value.rcvd.code == 1008
    assert f"credentials revoked: principal {name}" in closed.value.rcvd.reason


async def test_sighup_reloads_principals_and_roles(auth_path: Path, bridges: list[BridgeProcess]) -> None:
    """A removed principal's session is closed, a changed role applies at once, a new token works."""
    alice = add_principal(auth_path, "alice", "tester")
    bob = add_principal(auth_path, "bob", "viewer")
    bridge = BridgeProcess(args=["--auth-file", str(auth_path)]).start()
    bridges.append(bridge)
    a = await wire(bridge.url, alice)
    b = await wire(bridge.url, bob)
    await roundtrip(a)
    await b.send({"op": "advertise", "topic": "/cmd_vel", "type": TWIST, "id": "before"})
    assert "forbidden: role viewer" in (await b.expect(op="status", id="before"))["msg"]

    carol = add_principal(auth_path, "carol", "viewer")
    with pytest.raises(InvalidStatus) as refused:  # the running bridge does not know it yet
        await wire(bridge.url, carol)
    assert refused.value.response.status_code == 401
    remove_principal(auth_path, "alice")
    text = auth_path.read_text()
    auth_path.write_text(text.replace('[principals.bob]\nrole = "viewer"',
                                      '[principals.bob]\nrole = "tester"'))

    await reload_revoking(bridge, a, "alice")
    await b.send({"op": "advertise", "topic": "/cmd_vel", "type": TWIST, "id": "after"})
    await roundtrip(b)
    assert not [op for op in b.backlog if op.get("id") == "after"]  # now a tester: allowed
    c = await wire(bridge.url, carol)
    await roundtrip(c)
    log = bridge.log()
    assert not any(token[:12] in log for token in (alice, bob, carol))
    await b.close()
    await c.close()


async def test_a_token_rotated_under_the_same_name_revokes_the_old_sessions(
    auth_path: Path, bridges: list[BridgeProcess]
) -> None:
    """alice's token replaced (remove-principal, then add-principal alice with the same role)
    and SIGHUP: her session on the old token is closed as revoked, bob's goes on, the new
    token opens a session and the old one is refused."""
    old = add_principal(auth_path, "alice", "tester")
    bob = add_principal(auth_path, "bob", "viewer")
    bridge = BridgeProcess(args=["--auth-file", str(auth_path)]).start()
    bridges.append(bridge)
    a = await wire(bridge.url, old)
    b = await wire(bridge.url, bob)
    await roundtrip(a)

    def cli(*args: str) -> str:
        done = subprocess.run([sys.executable, "-m", "bridge_server", *args, "--auth-file",
                               str(auth_path)], cwd=ROOT, env=ros_env(), capture_output=True,
                              text=True, timeout=60, check=True)
        return done.stdout.strip()

    cli("remove-principal", "alice")
    new = cli("add-principal", "alice", "--role", "tester")
    assert new and new != old
    await reload_revoking(bridge, a, "alice")
    await roundtrip(b)
    again = await wire(bridge.url, new)
    await roundtrip(again)
    with pytest.raises(InvalidStatus) as refused:
        await wire(bridge.url, old)
    assert refused.value.response.status_code == 401
    await again.close()
    await b.close()


async def test_an_auth_file_that_does_not_load_changes_nothing(
    auth_path: Path, bridges: list[BridgeProcess]
) -> None:
    """A broken file on SIGHUP: an error naming the problem; sessions and tokens stay valid."""
    bob = add_principal(auth_path, "bob", "viewer")
    bridge = BridgeProcess(args=["--auth-file", str(auth_path)]).start()
    bridges.append(bridge)
    b = await wire(bridge.url, bob)
    auth_path.write_text(auth_path.read_text() + "\n[principals.eve\n")
    reload(bridge, r"ERROR .*reloading the auth file failed, the old one stays: .*not valid TOML")
    await roundtrip(b)
    again = await wire(bridge.url, bob)
    await roundtrip(again)
    await b.close()
    await again.close()


async def test_sighup_reloads_the_certificate(tmp_path: Path, bridges: list[BridgeProcess]) -> None:
    """New handshakes get the new certificate, open connections keep theirs; a bad file is
    refused and the certificate in use stays."""
    import trustme

    first, second = trustme.CA(), trustme.CA()
    cert = tmp_path / "server.pem"
    first.issue_cert("127.0.0.1").private_key_and_cert_chain_pem.write_to_path(str(cert))
    bridge = BridgeProcess(args=["--certfile", str(cert)]).start()
    bridges.append(bridge)
    url = f"wss://127.0.0.1:{bridge.port}"
    trust_first, trust_second = ssl.create_default_context(), ssl.create_default_context()
    first.configure_trust(trust_first)
    second.configure_trust(trust_second)
    old = await wire(url, ssl_context=trust_first)

    second.issue_cert("127.0.0.1").private_key_and_cert_chain_pem.write_to_path(str(cert))
    reload(bridge, r"reloaded the TLS certificate")
    new = await wire(url, ssl_context=trust_second)
    await roundtrip(new)
    with pytest.raises(ssl.SSLCertVerificationError):
        await wire(url, ssl_context=trust_first)
    await roundtrip(old)

    cert.write_text("not a certificate\n")
    reload(bridge, r"ERROR .*reloading the TLS certificate failed, the old one stays")
    again = await wire(url, ssl_context=trust_second)
    await roundtrip(again)
    for ws in (old, new, again):
        await ws.close()


async def test_workers_pass_sighup_on(auth_path: Path, bridges: list[BridgeProcess]) -> None:
    """With --workers, SIGHUP to the supervisor reloads every worker."""
    bridge = BridgeProcess(args=["--workers", "2", "--auth-file", str(auth_path)]).start()
    bridges.append(bridge)
    dave = add_principal(auth_path, "dave", "viewer")
    start = len(bridge.lines)
    assert bridge.proc is not None
    bridge.proc.send_signal(signal.SIGHUP)
    for worker in ("w0", "w1"):
        bridge.wait_for_line(rf"^\[{worker}\] .*reloaded the auth file", start=start)
    for _ in range(4):  # whichever worker takes the connection knows the new token
        ws = await wire(bridge.url, dave)
        await roundtrip(ws)
        await ws.close()


def test_remove_principal_keeps_the_rest_of_the_file(auth_path: Path) -> None:
    """remove-principal drops one [principals.NAME] table; comments and the others stay."""
    add_principal(auth_path, "alice", "viewer")
    add_principal(auth_path, "bob", "tester")
    auth_path.write_text(auth_path.read_text() + "# a comment at the end\n")
    done = subprocess.run(
        [sys.executable, "-m", "bridge_server", "remove-principal", "alice",
         "--auth-file", str(auth_path)],
        cwd=ROOT, env=ros_env(), capture_output=True, text=True, timeout=60,
    )
    assert done.returncode == 0, done.stderr
    assert "alice removed" in done.stderr and "SIGHUP" in done.stderr
    config = load_auth_file(auth_path)
    assert [p.name for p in config.principals] == ["bob"]
    assert set(config.roles) >= {"viewer", "operator", "admin", "tester"}
    assert auth_path.read_text().endswith("# a comment at the end\n")
    with pytest.raises(AuthFileError, match=r"no principal 'alice' \(principals: bob\)"):
        remove_principal(auth_path, "alice")
