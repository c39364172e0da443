"""Our client and CLI against a real TLS bridge with tokens: token=, ssl=, distinct errors."""

from __future__ import annotations

import subprocess
import sys
from typing import Any

import pytest

import roslibpy_lite
from roslibpy_lite import ConnectionClosed, Forbidden, NotAuthenticated, TLSError, UsageError
from roslibpy_lite.api import ConnectionState
from tests.helpers import ROOT, BridgeProcess, async_wait_until, ros_env
from tests.security.support import AuthFile, Certs


def _url(bridge: BridgeProcess) -> str:
    return f"wss://127.0.0.1:{bridge.port}"


async def test_connect_with_token_and_ca_file(
    tls_bridge: BridgeProcess, certs: Certs, auth: AuthFile
) -> None:
    """connect(token=, ssl=<CA file>) reaches a wss:// bridge that requires a token."""
    async with roslibpy_lite.connect(_url(tls_bridge), token=auth.tokens["viewer"],
                                     ssl=str(certs.ca)) as ros:
        reply = await ros.call_service("/rosapi/get_ros_version",
                                       "rosapi_msgs/srv/GetROSVersion", {})
        assert reply["version"] == 2


async def test_refused_token_is_not_retried(tls_bridge: BridgeProcess, certs: Certs) -> None:
    """A wrong token raises NotAuthenticated after one attempt, even with reconnect on."""
    start = len(tls_bridge.lines)
    with pytest.raises(NotAuthenticated, match="refused our token") as info:
        await roslibpy_lite.connect(_url(tls_bridge), token="not-the-token",
                                    ssl=certs.context(), open_timeout=30)
    assert "not-the-token" not in str(info.value)
    # The bridge's log is read from its stderr as it comes: wait for the refusal line.
    def refusals() -> int:
        return sum("wrong token" in line for line in tls_bridge.lines[start:])

    await async_wait_until(lambda: refusals() >= 1, 10.0, "the bridge's refusal line")
    assert refusals() == 1  # connect() raised after one attempt: no second refusal


async def test_forbidden_ops_raise_forbidden(
    tls_bridge: BridgeProcess, certs: Certs, auth: AuthFile, topic: str
) -> None:
    """A viewer's advertise and service call raise Forbidden naming the op, name and role."""
    async with roslibpy_lite.connect(_url(tls_bridge), token=auth.tokens["viewer"],
                                     ssl=certs.context()) as ros:
        with pytest.raises(Forbidden, match=f"role viewer may not publish on {topic}"):
            await ros.advertise(topic, "std_msgs/msg/String")
        with pytest.raises(Forbidden, match="call_service"):
            await ros.call_service(topic + "_srv", "std_srvs/srv/SetBool", {"data": True},
                                   timeout=10)


async def test_untrusted_certificate_is_one_line_tls_error(
    tls_bridge: BridgeProcess, certs: Certs, auth: AuthFile
) -> None:
    """A bridge whose CA the client does not trust gives TLSError in one line, not retried."""
    with pytest.raises(TLSError) as info:
        await roslibpy_lite.connect(_url(tls_bridge), token=auth.tokens["viewer"],
                                    ssl=str(certs.other_ca), open_timeout=30)
    text = str(info.value)
    assert "\n" not in text and "certificate" in text and "--cafile" in text


async def test_mutual_tls_without_a_client_certificate(make_bridge: Any, certs: Certs) -> None:
    """A bridge that requires client certificates: without one the client gets TLSError."""
    bridge = make_bridge("--certfile", str(certs.server), "--client-ca", str(certs.client_ca))
    with pytest.raises(TLSError, match="client certificate"):
        ros = await roslibpy_lite.connect(_url(bridge), ssl=certs.context(), open_timeout=10)
        await ros.call_service("/rosapi/get_ros_version", "rosapi_msgs/srv/GetROSVersion", {})
    async with roslibpy_lite.connect(_url(bridge), ssl=certs.context(client_cert=True)) as ros:
        await ros.call_service("/rosapi/get_ros_version", "rosapi_msgs/srv/GetROSVersion", {})


async def test_policy_close_is_not_reconnected(make_bridge: Any, topic: str) -> None:
    """When the bridge closes us with 1008 (an op flood), the client closes instead of looping."""
    bridge = make_bridge("--max-op-rate", "10", "--op-burst", "10")
    ros = await roslibpy_lite.connect(bridge.url)
    pub = await ros.advertise(topic, "std_msgs/msg/String")
    closed = ros.state_changes()
    for i in range(200):
        await pub.publish({"data": str(i)})
    async for state in closed:
        if state is ConnectionState.CLOSED:
            break
    assert ros.connects == 1
    with pytest.raises(ConnectionClosed):
        await ros.call_service("/rosapi/get_ros_version", "rosapi_msgs/srv/GetROSVersion", {})
    await ros.close()


def test_ssl_option_needs_a_wss_url() -> None:
    """ssl= with a ws:// URL is a usage error, said at once."""
    with pytest.raises(UsageError, match="wss://"):
        roslibpy_lite.connect("ws://127.0.0.1:9", ssl="ca.pem")


def _cli(*args: str, **env: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "roslibpy_lite.cli", *args], cwd=ROOT,
                          env=ros_env(**env), capture_output=True, text=True, timeout=60)


def test_cli_token_and_cafile(tls_bridge: BridgeProcess, certs: Certs, auth: AuthFile) -> None:
    """The CLI takes --token/--cafile, or $ROSLIBPY_LITE_TOKEN/$ROSLIBPY_LITE_CAFILE."""
    url = _url(tls_bridge)
    out = _cli("--url", url, "--token", auth.tokens["viewer"], "--cafile", str(certs.ca),
               "topic", "list")
    assert out.returncode == 0 and "/rosout" in out.stdout, out.stderr
    out = _cli("topic", "list", ROSLIBPY_LITE_URL=url, ROSLIBPY_LITE_TOKEN=auth.tokens["viewer"],
               ROSLIBPY_LITE_CAFILE=str(certs.ca))
    assert out.returncode == 0 and "/rosout" in out.stdout, out.stderr


def test_cli_refused_token_and_bad_certificate(tls_bridge: BridgeProcess, certs: Certs) -> None:
    """A wrong token or an untrusted certificate: exit 3 with one line saying which."""
    url = _url(tls_bridge)
    out = _cli("--url", url, "--token", "wrong-token", "--cafile", str(certs.ca), "topic", "list")
    assert out.returncode == 3
    assert "refused our token" in out.stderr and "--token" in out.stderr
    assert "wrong-token" not in out.stderr and len(out.stderr.strip().splitlines()) == 1
    out = _cli("--url", url, "--token", "x", "--cafile", str(certs.other_ca), "topic", "list")
    assert out.returncode == 3 and "certificate" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1


def test_cli_viewer_is_refused_when_it_publishes(
    tls_bridge: BridgeProcess, certs: Certs, auth: AuthFile, topic: str
) -> None:
    """`topic pub` as a viewer over wss fails with one line saying the role may not publish."""
    out = _cli("--url", _url(tls_bridge), "--token", auth.tokens["viewer"], "--cafile",
               str(certs.ca), "topic", "pub", topic, "std_msgs/msg/String", "{data: hi}",
               "--once")
    assert out.returncode == 6, out
    assert "forbidden" in out.stderr and "viewer" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1


def test_cli_send_goal_as_viewer_is_never_reported_accepted(
    auth_bridge: BridgeProcess, auth: AuthFile, ros_node: Any, topic: str
) -> None:
    """`action send_goal` as a viewer: the refusal, exit 6, and no "Goal accepted" line;
    an admin's goal is reported accepted (the bridge says when the server accepted it)."""
    from tests.bridge.action_support import FIB, FibServer

    server = FibServer(ros_node, topic)
    try:
        def send(role: str) -> subprocess.CompletedProcess[str]:
            return _cli("--url", auth_bridge.url, "--token", auth.tokens[role], "action",
                        "send_goal", topic, FIB, "{order: 2}", "--wait", "10")

        out = send("viewer")
        assert out.returncode == 6, out
        assert "Goal accepted" not in out.stdout, out
        assert "forbidden: role viewer may not send_action_goal" in out.stderr, out
        assert len(out.stderr.strip().splitlines()) == 1, out
        out = send("admin")
        assert out.returncode == 0, out
        assert "Goal accepted with ID: send_action_goal:" in out.stdout, out
        assert out.stdout.rstrip().endswith("Goal finished with status: SUCCEEDED")
    finally:
        server.destroy()
