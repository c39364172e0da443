"""Fixtures of the security tests: certificates, the auth file, a bridge that requires tokens."""

from __future__ import annotations

from collections.abc import AsyncIterator, Callable, Iterator
from typing import Any

import pytest

from tests.helpers import BridgeProcess, WireClient
from tests.security.support import AuthFile, Certs, make_auth_file, make_certs, wire


@pytest.fixture(scope="session")
def certs(tmp_path_factory: pytest.TempPathFactory) -> Certs:
    """CA, server and client certificates made by trustme for this run."""
    return make_certs(tmp_path_factory.mktemp("certs"))


@pytest.fixture(scope="session")
def auth(tmp_path_factory: pytest.TempPathFactory) -> AuthFile:
    """The test auth file (see support.ROLES; one token per role)."""
    return make_auth_file(tmp_path_factory.mktemp("auth"))


@pytest.fixture(scope="module")
def auth_bridge(auth: AuthFile) -> Iterator[BridgeProcess]:
    """A bridge that requires a token (plain ws), shared by a test module."""
    proc = BridgeProcess(args=["--auth-file", str(auth.path)]).start()
    yield proc
    proc.stop()


@pytest.fixture(scope="module")
def debug_bridge(auth: AuthFile) -> Iterator[BridgeProcess]:
    """A bridge requiring tokens, logging at DEBUG (websockets' request lines and headers),
    shared by a test module."""
    proc = BridgeProcess(args=["--auth-file", str(auth.path), "--log-level", "DEBUG"]).start()
    yield proc
    proc.stop()


@pytest.fixture(scope="module")
def tls_bridge(certs: Certs, auth: AuthFile) -> Iterator[BridgeProcess]:
    """A bridge serving wss:// and requiring tokens, shared by a test module."""
    proc = BridgeProcess(args=["--certfile", str(certs.server), "--auth-file", str(auth.path)])
    proc.start()
    yield proc
    proc.stop()


@pytest.fixture
async def connect_as(
    auth_bridge: BridgeProcess, auth: AuthFile
) -> AsyncIterator[Callable[..., Any]]:
    """Open a connection to ``auth_bridge`` as the principal of a role (closed afterwards)."""
    opened: list[WireClient] = []

    async def open_as(role: str, url: str | None = None) -> WireClient:
        client = await wire(url or auth_bridge.url, auth.tokens[role])
        opened.append(client)
        return client

    yield open_as
    for client in opened:
        await client.close()
