"""Helpers for the security tests: certificates, auth files, connections with tokens."""

from __future__ import annotations

import signal
import ssl
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rosbridge_core.security.auth import EXAMPLE_ROLES, hash_token, new_token
from tests.helpers import BridgeProcess, WireClient, open_wire

ROLES = EXAMPLE_ROLES + """
[roles.tester]
subscribe = ["*"]
publish = ["/op/*", "/cmd_vel"]
call_service = ["/op/*"]
deny.publish = ["/op/forbidden"]

[roles.nothing]

[roles.narrow]
introspection = ["/seen*"]
params = ["/seen_node:*"]

[roles.server]
serve_service = ["*"]

[roles.prober]
call_service = ["/probe/*"]
subscribe = ["/probe/*"]
publish = ["/probe/*"]
params = ["*_display"]

[roles.blind]
introspection = ["*"]
deny.introspection = ["*"]
"""
"""The example roles (viewer, operator, admin) and the tests' own; a principal per role."""


@dataclass
class Certs:
    """Files made by trustme for one test session."""

    ca: Path
    server: Path
    client_ca: Path
    client: Path
    other_ca: Path

    def context(self, client_cert: bool = False, ca: Path | None = None) -> ssl.SSLContext:
        """A client TLS context trusting our CA (and presenting a client certificate)."""
        ctx = ssl.create_default_context(cafile=str(ca or self.ca))
        if client_cert:
            ctx.load_cert_chain(str(self.client))
        return ctx


def make_certs(tmp: Path) -> Certs:
    """A CA, a server certificate for 127.0.0.1, and a client CA with one client certificate."""
    import trustme

    ca = trustme.CA()
    client_ca = trustme.CA()
    other = trustme.CA()
    certs = Certs(tmp / "ca.pem", tmp / "server.pem", tmp / "client_ca.pem", tmp / "client.pem",
                  tmp / "other_ca.pem")
    ca.cert_pem.write_to_path(str(certs.ca))
    ca.issue_cert("127.0.0.1", "localhost").private_key_and_cert_chain_pem.write_to_path(
        str(certs.server))
    client_ca.cert_pem.write_to_path(str(certs.client_ca))
    client_ca.issue_cert("robot-ui@example.com").private_key_and_cert_chain_pem.write_to_path(
        str(certs.client))
    other.cert_pem.write_to_path(str(certs.other_ca))
    return certs


@dataclass
class AuthFile:
    """An auth file with the roles above and a principal (and its token) per role."""

    path: Path
    tokens: dict[str, str] = field(default_factory=dict)


def make_auth_file(tmp: Path) -> AuthFile:
    """Write the test auth file; tokens are made now and kept only in memory."""
    principals = [(r, r) for r in ("viewer", "tester", "admin", "nothing", "narrow", "server",
                                   "prober", "blind")]
    principals.append(("server_b", "server"))  # a second principal with the same role
    return write_auth_file(tmp / "auth.toml", ROLES, principals, "_user")


def write_auth_file(path: Path, text: str, principals: list[tuple[str, str]],
                    suffix: str = "") -> AuthFile:
    """Write ``text`` (roles, limits) and a principal ``name + suffix`` per ``(name, role)``,
    each with a new token (kept in memory, under ``name``)."""
    auth = AuthFile(path)
    for name, role in principals:
        token = auth.tokens[name] = new_token()
        text += (f'\n[principals.{name}{suffix}]\nrole = "{role}"\n'
                 f'token_hash = "{hash_token(token)}"\n')
    auth.path.write_text(text)
    return auth


async def wire(
    url: str,
    token: str | None = None,
    *,
    ssl_context: ssl.SSLContext | None = None,
    headers: dict[str, str] | None = None,
    **kwargs: Any,
) -> WireClient:
    """A raw websocket peer; ``token`` goes into an ``Authorization: Bearer`` header."""
    extra = dict(headers or {})
    if token is not None:
        extra["Authorization"] = f"Bearer {token}"
    return await open_wire(url, additional_headers=extra, ssl=ssl_context, **kwargs)


async def bridge_entities(ros_node: Any, bridge: BridgeProcess, admin: WireClient,
                          marker: str) -> dict[str, set[str]]:
    """The bridge node's ROS entities (``subscriptions``, ``publishers``, ``services``,
    ``clients``: names), as this node's graph sees them once the bridge's newest ones are in
    it: ``admin`` (a principal allowed to) subscribes and advertises ``marker`` now, and each
    kind of endpoint is announced in order, so whatever the bridge made before is seen too."""
    from rclpy._rclpy_pybind11 import NodeNameNonExistentError

    from tests.helpers import async_wait_until

    await admin.send({"op": "subscribe", "topic": marker, "type": "std_msgs/msg/String"})
    await admin.send({"op": "advertise", "topic": marker, "type": "std_msgs/msg/String"})
    ns, _, name = bridge.node_name.rpartition("/")
    ns = ns or "/"
    graph = {
        "subscriptions": ros_node.get_subscriber_names_and_types_by_node,
        "publishers": ros_node.get_publisher_names_and_types_by_node,
        "services": ros_node.get_service_names_and_types_by_node,
        "clients": ros_node.get_client_names_and_types_by_node,
    }

    def seen() -> dict[str, set[str]] | None:
        try:
            found = {kind: {n for n, _ in read(name, ns)} for kind, read in graph.items()}
        except NodeNameNonExistentError:  # not discovered yet
            return None
        ready = marker in found["subscriptions"] and marker in found["publishers"]
        return found if ready else None

    found: dict[str, set[str]] = await async_wait_until(
        seen, 20, f"the bridge's endpoints on {marker}")
    return found


class WatcherAuth:
    """An auth file with one principal (role ``watcher``: subscribe to anything) that a test
    narrows (``deny.subscribe`` on ``/secret*``) and then reloads with SIGHUP."""

    ROLES = '[roles.watcher]\nsubscribe = ["*"]\n'

    def __init__(self, directory: Path) -> None:
        self.token = new_token()
        self.path = directory / "auth.toml"
        self._principal = (f'\n[principals.dora]\nrole = "watcher"\n'
                           f'token_hash = "{hash_token(self.token)}"\n')
        self.path.write_text(self.ROLES + self._principal)

    def narrow(self, bridge: BridgeProcess) -> str:
        """Deny ``/secret*`` to the role, send the bridge SIGHUP; its reload log line."""
        self.path.write_text(self.ROLES + 'deny.subscribe = ["/secret*"]\n' + self._principal)
        start = len(bridge.lines)
        assert bridge.proc is not None
        bridge.proc.send_signal(signal.SIGHUP)
        return bridge.wait_for_line(r"reloaded the auth file", start=start)
