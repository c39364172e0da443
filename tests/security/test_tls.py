"""TLS at the bridge: wss:// with certificates made by trustme, mutual TLS, and tokens over wss."""

from __future__ import annotations

import ssl
from typing import Any

import pytest
from websockets.exceptions import ConnectionClosed, InvalidHandshake

from tests.helpers import BridgeProcess, roundtrip
from tests.security.support import AuthFile, Certs, wire


def wss(bridge: BridgeProcess) -> str:
    """The wss:// URL of a TLS bridge."""
    return f"wss://127.0.0.1:{bridge.port}"


async def test_wss_with_a_token(tls_bridge: BridgeProcess, certs: Certs, auth: AuthFile) -> None:
    """A client trusting the CA connects over wss:// with a token; the ready line says wss."""
    ws = await wire(wss(tls_bridge), auth.tokens["viewer"], ssl_context=certs.context())
    await roundtrip(ws)
    await ws.close()
    assert any("listening on wss://" in line for line in tls_bridge.lines)


async def test_viewer_over_wss_is_refused_when_it_publishes(
    tls_bridge: BridgeProcess, certs: Certs, auth: AuthFile
) -> None:
    """The done-when scenario: a viewer over wss may subscribe but its publish is forbidden."""
    ws = await wire(wss(tls_bridge), auth.tokens["viewer"], ssl_context=certs.context())
    await ws.send({"op": "subscribe", "topic": "/chatter", "type": "std_msgs/msg/String",
                   "id": "s"})
    await ws.send({"op": "publish", "topic": "/chatter", "msg": {"data": "hi"}, "id": "p"})
    status = await ws.expect(op="status", id="p")
    assert "forbidden" in status["msg"] and "viewer" in status["msg"]
    assert not any(op.get("id") == "s" for op in ws.backlog)
    await ws.close()


async def test_untrusted_certificate_is_a_certificate_error(
    tls_bridge: BridgeProcess, certs: Certs, auth: AuthFile
) -> None:
    """A client that does not trust the bridge's CA fails with a certificate verification error."""
    with pytest.raises(ssl.SSLCertVerificationError):
        await wire(wss(tls_bridge), auth.tokens["viewer"],
                   ssl_context=certs.context(ca=certs.other_ca))


async def test_mutual_tls_requires_a_client_certificate(make_bridge: Any, certs: Certs) -> None:
    """With --client-ca, a client without a certificate is refused; one with it connects."""
    bridge = make_bridge("--certfile", str(certs.server), "--client-ca", str(certs.client_ca))
    ws = await wire(wss(bridge), ssl_context=certs.context(client_cert=True))
    await roundtrip(ws)
    await ws.close()
    with pytest.raises((ssl.SSLError, OSError, InvalidHandshake, ConnectionClosed)):
        ws = await wire(wss(bridge), ssl_context=certs.context(client_cert=False))
        await roundtrip(ws)  # TLS 1.3 reports the missing certificate on the first read


async def test_workers_serve_wss(make_bridge: Any, certs: Certs, auth: AuthFile) -> None:
    """With --workers, every worker serves TLS and checks tokens; the ready line says wss."""
    bridge = make_bridge("--workers", "2", "--certfile", str(certs.server),
                         "--auth-file", str(auth.path))
    assert any("listening on wss://" in line and "workers" in line for line in bridge.lines)
    for _ in range(4):  # the kernel spreads connections over the workers
        ws = await wire(wss(bridge), auth.tokens["viewer"], ssl_context=certs.context())
        await roundtrip(ws)
        await ws.close()


def test_tls_context_requires_tls_1_2_and_client_certificates(certs: Certs) -> None:
    """The server context refuses TLS below 1.2, and --client-ca makes a certificate required."""
    from bridge_server.front.handshake import Security
    from rosbridge_core.security import SecurityConfig

    plain = Security(SecurityConfig(certfile=str(certs.server))).ssl_context()
    mutual = Security(SecurityConfig(certfile=str(certs.server),
                                     client_ca=str(certs.client_ca))).ssl_context()
    assert plain is not None and mutual is not None
    assert plain.minimum_version >= ssl.TLSVersion.TLSv1_2
    assert plain.verify_mode == ssl.CERT_NONE and mutual.verify_mode == ssl.CERT_REQUIRED
