"""The MCP server's HTTP door against real ``roslibpy-lite mcp --http`` processes, with the MCP
SDK's own HTTP client: a token on every address, TLS beyond loopback, Host and Origin checked,
each request logged with its peer, and a client on another address (a network namespace)."""

from __future__ import annotations

import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.helpers import ROOT, BridgeProcess, free_port, ros_env
from tests.mcp.http_support import (
    TOKEN,
    Namespace,
    attempt,
    mcp_http,
    netns_available,
    other_machine,
    start_args,
    write_token,
)

DEAD_URL = "ws://127.0.0.1:9"  # never dialled: a refused door stops the server before


@pytest.mark.parametrize(("extra", "named"), [
    (("--host", "0.0.0.0"), ("--http-certfile", "--http-token-file", "--insecure")),
    (("--host", "0.0.0.0", "--http-token-file", "TOKEN"), ("--http-certfile", "--insecure")),
    (("--host", "0.0.0.0", "--no-http-auth", "--http-certfile", "CERT"),
     ("--http-token-file", "--insecure")),
    ((), ("--http-token-file", "--no-http-auth")),
])
def test_an_unguarded_door_does_not_start(extra: tuple[str, ...], named: tuple[str, ...],
                                          tmp_path: Path) -> None:
    """Without TLS and a token on an address other machines reach, or without a token on
    loopback, the server exits at once with a usage error naming the flags to add."""
    token_file = write_token(tmp_path)
    args = [token_file if a == "TOKEN" else str(tmp_path / "c.pem") if a == "CERT" else a
            for a in extra]
    done = subprocess.run(start_args(DEAD_URL, free_port(), *args), cwd=ROOT, timeout=60,
                          env=ros_env(PYTHONPATH=str(ROOT)), capture_output=True, text=True)
    assert done.returncode == 2, done.stderr
    for flag in named:
        assert flag in done.stderr, (flag, done.stderr)
    assert TOKEN not in done.stderr


async def test_loopback_needs_the_token_and_logs_each_request(
    bridge: BridgeProcess, tmp_path: Path
) -> None:
    """On 127.0.0.1 a client without the token, or with another, gets 401 and no tools; with
    it, the tools; each request is logged with its peer and status, never the token."""
    with mcp_http(bridge.url, free_port(), tmp_path,
                  "--http-token-file", write_token(tmp_path)) as server:
        none = await attempt(server.url)
        assert none.tools is None and none.statuses[:1] == [401], none
        wrong = await attempt(server.url, token=TOKEN[:-1] + "x")
        assert wrong.tools is None and wrong.statuses[:1] == [401], wrong
        right = await attempt(server.url, token=TOKEN)
        assert right.tools is not None and "list_topics" in right.tools, right
        log = server.stderr()
    assert "POST /mcp from 127.0.0.1:" in log and ": 401 (" in log and ": 200 (" in log, log
    assert TOKEN not in log and TOKEN[:-1] + "x" not in log


@pytest.mark.parametrize(("header", "status"), [
    ({"Host": "evil.example"}, 421),
    ({"Origin": "http://evil.example"}, 403),
])
async def test_a_foreign_host_or_origin_is_refused_even_with_the_token(
    bridge: BridgeProcess, tmp_path: Path, header: dict[str, str], status: int
) -> None:
    """DNS-rebinding protection on loopback: a request naming another Host, or sent from
    another Origin, is refused though it carries the right token."""
    with mcp_http(bridge.url, free_port(), tmp_path,
                  "--http-token-file", write_token(tmp_path)) as server:
        refused = await attempt(server.url, token=TOKEN, headers=header)
        assert refused.tools is None and refused.statuses[:1] == [status], refused


async def test_no_http_auth_serves_loopback_and_warns(bridge: BridgeProcess,
                                                      tmp_path: Path) -> None:
    """--no-http-auth is the explicit way to serve loopback without a token: it serves, and
    says at start that every local user may act on the robot."""
    with mcp_http(bridge.url, free_port(), tmp_path, "--no-http-auth") as server:
        served = await attempt(server.url)
        assert served.tools is not None, served
        assert "--no-http-auth" in server.stderr() and "WARNING" in server.stderr()


@pytest.fixture(scope="module")
def far() -> Iterator[Namespace]:
    """Another machine: a network namespace reaching this one over a veth pair."""
    if not netns_available():
        pytest.skip("network namespaces need root and iproute2 ('ip')")
    with other_machine() as ns:
        yield ns


def _certs(tmp: Path, ip: str) -> tuple[str, str]:
    """A trustme CA (its PEM's path) and a server certificate for ``ip`` (key and chain)."""
    import trustme

    ca = trustme.CA()
    ca_path, server = tmp / "ca.pem", tmp / "server.pem"
    ca.cert_pem.write_to_path(str(ca_path))
    ca.issue_cert(ip).private_key_and_cert_chain_pem.write_to_path(str(server))
    return str(ca_path), str(server)


async def test_from_another_address_over_tls_with_the_token(
    bridge: BridgeProcess, far: Namespace, tmp_path: Path
) -> None:
    """Served on an address another machine reaches, with TLS and a token: from that machine
    the SDK's client lists the tools with the token, gets 401 without it, and 421/403 with a
    foreign Host or Origin; the log names the far address."""
    ca, cert = _certs(tmp_path, far.near_ip)
    with mcp_http(bridge.url, free_port(), tmp_path, "--http-token-file", write_token(tmp_path),
                  "--http-certfile", cert, host=far.near_ip, scheme="https") as server:
        served = far.attempt(server.url, TOKEN, cafile=ca)
        assert served.tools is not None and "list_topics" in served.tools, served
        assert far.attempt(server.url, cafile=ca).statuses[:1] == [401]
        rebound = far.attempt(server.url, TOKEN, {"Host": "evil.example"}, cafile=ca)
        assert rebound.tools is None and rebound.statuses[:1] == [421], rebound
        other = far.attempt(server.url, TOKEN, {"Origin": "http://evil.example"}, cafile=ca)
        assert other.tools is None and other.statuses[:1] == [403], other
        log = server.stderr()
    assert f"POST /mcp from {far.far_ip}:" in log and TOKEN not in log, log


async def test_insecure_serves_another_address_with_a_loud_warning(
    bridge: BridgeProcess, far: Namespace, tmp_path: Path
) -> None:
    """--insecure lets plain HTTP serve an outside address (the token still asked), and the
    warning at start names what is missing."""
    with mcp_http(bridge.url, free_port(), tmp_path, "--http-token-file", write_token(tmp_path),
                  "--insecure", host=far.near_ip) as server:
        assert far.attempt(server.url, TOKEN).tools is not None
        assert far.attempt(server.url).statuses[:1] == [401]
        log = server.stderr()
    assert "WARNING" in log and "--insecure" in log and "without TLS" in log, log
