"""``roslibpy-lite mcp --http`` as a child process, the MCP SDK's own HTTP client against it
(recording each HTTP status the server answered), and a network namespace to reach it from
another address."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import socket
import ssl
import subprocess
import sys
import time
from collections.abc import AsyncIterator, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tests.helpers import ROOT, ros_env

TOKEN = "mcp-http-" + "k" * 32
"""The HTTP bearer token the tests' servers are given (a test's own: not a secret)."""


@dataclass
class McpHttp:
    """A running ``roslibpy-lite mcp --http`` and where its stderr goes."""

    proc: subprocess.Popen[bytes]
    url: str
    log: Path

    def stderr(self) -> str:
        """What the server wrote to stderr so far."""
        return self.log.read_text(errors="replace")


def start_args(url: str, port: int, *extra: str) -> list[str]:
    """The command line of ``roslibpy-lite mcp --url URL --http PORT extra...``."""
    return [sys.executable, "-m", "roslibpy_lite.cli", "mcp", "--url", url, "--http", str(port),
            *extra]


@contextlib.contextmanager
def mcp_http(url: str, port: int, tmp: Path, *extra: str, host: str = "127.0.0.1",
             scheme: str = "http") -> Iterator[McpHttp]:
    """``roslibpy-lite mcp --http PORT --host HOST extra...`` as a child process; yields it once
    it listens (a TCP connect is the only sign a listener gives)."""
    log = tmp / f"mcp-http-{port}.log"
    with log.open("wb") as err:
        proc = subprocess.Popen(start_args(url, port, "--host", host, *extra), cwd=ROOT,
                                env=ros_env(PYTHONPATH=str(ROOT)), stdin=subprocess.DEVNULL,
                                stderr=err)
    server = McpHttp(proc, f"{scheme}://{host}:{port}/mcp", log)
    try:
        deadline = time.monotonic() + 60  # a python start and a connect on a loaded machine
        while True:
            with contextlib.suppress(OSError), socket.create_connection((host, port), 1):
                break
            assert proc.poll() is None, (f"the mcp server exited with {proc.returncode}: "
                                         f"{server.stderr()}")
            assert time.monotonic() < deadline, "the mcp server never listened"
            time.sleep(0.05)
        yield server
    finally:
        proc.terminate()
        proc.wait(10)


def write_token(tmp: Path, token: str = TOKEN) -> str:
    """A token file holding ``token``; its path."""
    path = tmp / "http.token"
    path.write_text(token + "\n")
    return str(path)


@dataclass
class Outcome:
    """What an MCP client got: the HTTP statuses it was answered, and the tools or the error."""

    statuses: list[int] = field(default_factory=list)
    tools: list[str] | None = None
    error: str | None = None


@contextlib.asynccontextmanager
async def http_client(url: str, token: str | None = None,
                      headers: dict[str, str] | None = None, cafile: str | None = None,
                      statuses: list[int] | None = None) -> AsyncIterator[Any]:
    """The SDK's ``Client`` over streamable HTTP (``token`` as a bearer token, more
    ``headers``, TLS trusting ``cafile``; each HTTP status answered appended to
    ``statuses``)."""
    import httpx2
    from mcp import Client
    from mcp.client.streamable_http import streamable_http_client

    async def seen(response: Any) -> None:
        if statuses is not None:
            statuses.append(response.status_code)

    sent = dict(headers or {})
    if token is not None:
        sent["Authorization"] = f"Bearer {token}"
    verify: Any = ssl.create_default_context(cafile=cafile) if cafile else True
    async with httpx2.AsyncClient(headers=sent, verify=verify, timeout=30,
                                  event_hooks={"response": [seen]}) as http:
        transport = streamable_http_client(url, http_client=http)
        async with Client(transport, read_timeout_seconds=60, mode="legacy") as client:
            yield client


async def attempt(url: str, token: str | None = None, headers: dict[str, str] | None = None,
                  cafile: str | None = None) -> Outcome:
    """Initialize and list tools with :func:`http_client`: what it got."""
    outcome = Outcome()
    try:
        async with http_client(url, token, headers, cafile, outcome.statuses) as client:
            outcome.tools = [t.name for t in (await client.list_tools()).tools]
    except Exception as exc:  # the SDK wraps the transport's failure in exception groups
        outcome.error = f"{type(exc).__name__}: {exc}"
    return outcome


ATTEMPT_SCRIPT = """
import asyncio, json, sys
from tests.mcp.http_support import attempt
url, token, headers, cafile = json.loads(sys.argv[1])
print(json.dumps(asyncio.run(attempt(url, token, headers, cafile)).__dict__))
"""


@dataclass
class Namespace:
    """A network namespace linked to this one by a veth pair: ``near_ip`` here,
    ``far_ip`` inside it."""

    name: str
    near_ip: str
    far_ip: str

    def attempt(self, url: str, token: str | None = None,
                headers: dict[str, str] | None = None, cafile: str | None = None) -> Outcome:
        """:func:`attempt` run by a Python process inside the namespace (from ``far_ip``)."""
        done = subprocess.run(
            ["ip", "netns", "exec", self.name, sys.executable, "-c", ATTEMPT_SCRIPT,
             json.dumps([url, token, headers, cafile])],
            cwd=ROOT, env=ros_env(PYTHONPATH=str(ROOT)), capture_output=True, text=True,
            timeout=90, check=False)
        assert done.returncode == 0, done.stderr
        return Outcome(**json.loads(done.stdout.strip().splitlines()[-1]))


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True)


def netns_available() -> bool:
    """Whether this process may make network namespaces (root, iproute2)."""
    return os.geteuid() == 0 and shutil.which("ip") is not None


@contextlib.contextmanager
def other_machine() -> Iterator[Namespace]:
    """A namespace with loopback and a /30 veth link to this one (10.200.N.1 here, .2 there);
    removed afterwards."""
    tag = os.getpid() % 10000
    subnet = f"10.200.{os.getpid() % 250}"
    ns = Namespace(f"rlmcp{tag}", f"{subnet}.1", f"{subnet}.2")
    near, far = f"rmh{tag}", f"rmf{tag}"
    _ip("netns", "add", ns.name)
    try:
        _ip("link", "add", near, "type", "veth", "peer", "name", far)
        _ip("link", "set", far, "netns", ns.name)
        _ip("addr", "add", f"{ns.near_ip}/30", "dev", near)
        _ip("link", "set", near, "up")
        inside = ["netns", "exec", ns.name, "ip"]
        _ip(*inside, "addr", "add", f"{ns.far_ip}/30", "dev", far)
        _ip(*inside, "link", "set", far, "up")
        _ip(*inside, "link", "set", "lo", "up")
        yield ns
    finally:
        with contextlib.suppress(subprocess.CalledProcessError):
            _ip("link", "del", near)  # takes its peer with it
        _ip("netns", "del", ns.name)
