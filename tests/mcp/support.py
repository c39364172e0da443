"""The MCP SDK's own client driving ``roslibpy-lite mcp`` as a child process over stdio."""

from __future__ import annotations

import asyncio
import contextlib
import sys
import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

from mcp import Client, StdioServerParameters
from std_srvs.srv import SetBool

from rosbridge_core.security.auth import hash_token, new_token
from tests.helpers import ROOT, ros_env


@contextlib.asynccontextmanager
async def mcp_stdio(url: str, token: str | None, tmp: Path, *extra: str,
                    **client: Any) -> AsyncIterator[Client]:
    """An MCP client of ``python -m roslibpy_lite.cli mcp --url URL`` (the token in a file;
    ``client``: more options of the SDK's ``Client``)."""
    args = ["-m", "roslibpy_lite.cli", "mcp", "--url", url, *extra]
    if token is not None:
        token_file = tmp / "agent.token"
        token_file.write_text(token + "\n")
        args += ["--token-file", str(token_file)]
    params = StdioServerParameters(command=sys.executable, args=args, cwd=ROOT,
                                   env=ros_env(PYTHONPATH=str(ROOT)))
    async with Client(params, read_timeout_seconds=60, **client) as session:
        yield session


def text(result: Any) -> str:
    """The text of a tool result (its text blocks, joined)."""
    return "\n".join(b.text for b in result.content if b.type == "text")


async def tool_names(client: Client) -> set[str]:
    """The names of the tools the server offers now."""
    return {t.name for t in (await client.list_tools(cache_mode="refresh")).tools}


async def until_tool(client: Client, name: str, timeout: float = 15.0) -> Any:
    """The tool ``name`` once the server lists it (the ROS graph has no event to await, so
    the listing is asked again until the bridge has discovered the entity)."""
    deadline = time.monotonic() + timeout
    while True:
        for tool in (await client.list_tools(cache_mode="refresh")).tools:
            if tool.name == name:
                return tool
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for the tool {name}")
        await asyncio.sleep(0.05)


async def until_listed(client: Client, tool: str, name: str, timeout: float = 15.0) -> None:
    """Wait until the listing tool ``tool`` (list_services...) names ``name``."""
    deadline = time.monotonic() + timeout
    while name not in text(await client.call_tool(tool, {})):
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {name} in {tool}")
        await asyncio.sleep(0.05)


def serve_setbool(ros_node: Any, name: str) -> list[bool]:
    """An rclpy std_srvs/SetBool service at ``name``; the list of the requests it got."""
    calls: list[bool] = []

    def handle(request: Any, response: Any) -> Any:
        calls.append(request.data)
        response.success = True
        response.message = f"set to {request.data}"
        return response

    ros_node.create_service(SetBool, name, handle)
    return calls


AGENT_ROLE = '[roles.agent]\nintrospection = ["*"]\n'


def agent_auth(path: Path, grants: str) -> str:
    """Write an auth file at ``path`` whose one principal has the role ``agent``
    (introspection on everything, plus ``grants``: TOML lines); its token."""
    token = new_token()
    path.write_text(AGENT_ROLE + grants + f'\n[principals.agent]\nrole = "agent"\n'
                    f'token_hash = "{hash_token(token)}"\n')
    return token
