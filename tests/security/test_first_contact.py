"""What a new user meets first: a missing token, TLS mistakes, a lock-out, a URL without a port."""

from __future__ import annotations

import asyncio
import gc
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

import roslibpy_lite
from roslibpy_lite import ConnectError, NotAuthenticated, TLSError
from roslibpy_lite.transports.websocket import with_default_port
from tests.helpers import ROOT, BridgeProcess, ros_env
from tests.security.support import AuthFile, Certs


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "roslibpy_lite.cli", *args], cwd=ROOT,
                          env=ros_env(), capture_output=True, text=True, timeout=60)


async def test_no_token_fails_at_connect(auth_bridge: BridgeProcess) -> None:
    """Without a token, connect() to an auth bridge raises NotAuthenticated saying how to give
    one, instead of reporting CONNECTED and failing at the first op."""
    with pytest.raises(NotAuthenticated) as info:
        await asyncio.wait_for(roslibpy_lite.connect(auth_bridge.url, open_timeout=30), 20)
    text = str(info.value)
    assert "requires a token" in text and "token=" in text
    assert "--token" in text and "$ROSLIBPY_LITE_TOKEN" in text


def test_cli_without_a_token_says_so_once(auth_bridge: BridgeProcess) -> None:
    """The CLI without a token exits 3 with one line naming --token (not 'send the auth op')."""
    out = _cli("--url", auth_bridge.url, "topic", "list")
    assert out.returncode == 3, out
    assert "requires a token" in out.stderr and out.stderr.count("--token") == 1
    assert len(out.stderr.strip().splitlines()) == 1


async def test_plain_ws_to_a_tls_port_says_use_wss(tls_bridge: BridgeProcess) -> None:
    """ws:// to a port that speaks TLS fails at once (not after open_timeout) saying wss://."""
    url = f"ws://127.0.0.1:{tls_bridge.port}"
    with pytest.raises(ConnectError, match=r"this port speaks TLS: use wss://127\.0\.0\.1"):
        await asyncio.wait_for(roslibpy_lite.connect(url, open_timeout=60), 30)


def test_the_tls_probe_leaves_nothing_open(tls_bridge: BridgeProcess) -> None:
    """The probe that tells a ws:// URL it reached a TLS port closes its socket before the
    error is raised: a caller whose loop ends with that error leaves nothing open (what
    was left is collected here, and its ResourceWarning fails the test)."""
    url = f"ws://127.0.0.1:{tls_bridge.port}"

    async def attempt() -> None:
        with pytest.raises(ConnectError, match="this port speaks TLS"):
            await roslibpy_lite.connect(url, open_timeout=60)

    asyncio.run(attempt())
    gc.collect()


async def test_certificate_for_another_name_says_so(make_bridge: Any, tmp_path: Path) -> None:
    """A certificate without this address in its subjectAltName is named as the problem, not
    the CA (which is trusted)."""
    import trustme

    ca = trustme.CA()
    server = tmp_path / "server.pem"
    ca.issue_cert("robot.example").private_key_and_cert_chain_pem.write_to_path(str(server))
    ca_file = tmp_path / "ca.pem"
    ca.cert_pem.write_to_path(str(ca_file))
    bridge = make_bridge("--certfile", str(server))
    with pytest.raises(TLSError) as info:
        await roslibpy_lite.connect(f"wss://127.0.0.1:{bridge.port}", ssl=str(ca_file))
    text = str(info.value)
    assert "not valid for 127.0.0.1" in text and "subjectAltName" in text
    assert "give the CA" not in text


def test_cli_prints_the_ca_hint_once(tls_bridge: BridgeProcess, certs: Certs, auth: AuthFile) -> None:
    """An untrusted certificate on the command line: one line, the --cafile hint once."""
    out = _cli("--url", f"wss://127.0.0.1:{tls_bridge.port}", "--token", auth.tokens["viewer"],
               "--cafile", str(certs.other_ca), "topic", "list")
    assert out.returncode == 3 and out.stderr.count("--cafile") == 1, out.stderr


async def test_lock_out_is_not_called_a_refused_token(make_bridge: Any, auth: AuthFile) -> None:
    """During a lock-out even the right token is refused: the error says why, and when to retry."""
    bridge = make_bridge("--auth-file", str(auth.path))
    for _ in range(5):
        with pytest.raises(NotAuthenticated, match="refused our token"):
            await roslibpy_lite.connect(bridge.url, token="wrong")
    with pytest.raises(NotAuthenticated) as info:
        await roslibpy_lite.connect(bridge.url, token=auth.tokens["viewer"])
    text = str(info.value)
    assert "too many failed authentication attempts" in text and "retry after" in text
    assert "refused our token" not in text


@pytest.mark.parametrize(
    ("url", "expected"),
    [("ws://127.0.0.1", "ws://127.0.0.1:9090"), ("ws://robot/path", "ws://robot:9090/path"),
     ("ws://robot:80", "ws://robot:80"), ("wss://robot.example", "wss://robot.example"),
     ("ws://[::1]", "ws://[::1]:9090"), ("ws://user@robot", "ws://user@robot:9090")],
)
def test_ws_url_without_port_means_the_rosbridge_port(url: str, expected: str) -> None:
    """A ws:// URL without a port goes to 9090; wss:// keeps 443 (a TLS proxy's port)."""
    assert with_default_port(url) == expected


async def test_security_md_private_ca_recipe_works(make_bridge: Any, tmp_path: Path) -> None:
    """SECURITY.md's private-CA commands, run as written (address 127.0.0.1), give a bridge
    certificate our client accepts with only the CA file."""
    import re

    text = (ROOT / "SECURITY.md").read_text()
    block = re.search(r"<!-- recipe: private-ca -->\n```bash\n(.*?)```", text, re.S)
    assert block is not None
    script = block.group(1).replace("IP:192.168.1.50", "IP:127.0.0.1")
    subprocess.run(["bash", "-euo", "pipefail", "-c", script], cwd=tmp_path, check=True,
                   capture_output=True, timeout=60)
    bridge = make_bridge("--certfile", str(tmp_path / "server.pem"),
                         "--keyfile", str(tmp_path / "server.key"))
    async with roslibpy_lite.connect(f"wss://127.0.0.1:{bridge.port}",
                                     ssl=str(tmp_path / "ca.pem")) as ros:
        reply = await ros.call_service("/rosapi/get_ros_version",
                                       "rosapi_msgs/srv/GetROSVersion", {})
    assert reply["version"] == 2
