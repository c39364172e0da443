"""An MCP (Model Context Protocol) server for a robot, on the roslibpy-lite client.

AI assistants and agents that speak MCP (Claude Desktop, Claude Code, IDE agents, agent
frameworks) list and use the robot's topics, services, actions and parameters as tools,
through a bridge or a relay, with the connection's own token: the bridge's role for that
token decides what the agent may do. Built on the official ``mcp`` SDK (the ``mcp`` extra)::

    roslibpy-lite mcp --url wss://relay.example.com/robot1 --token-file agent.token

See :mod:`roslibpy_lite.mcp.tools` for the tools and docs/guides/mcp.md for the set-up.
"""

from __future__ import annotations

try:
    import mcp  # noqa: F401  # the SDK: its absence is said once, here
except ImportError as exc:  # pragma: no cover - the extra is installed in the test suite
    raise ImportError(
        "roslibpy_lite.mcp needs the MCP SDK (the mcp package): install roslibpy-lite "
        "with its mcp extra, e.g. pip install './roslibpy_lite-<version>-py3-none-any.whl[mcp]'"
    ) from exc

from .door import HttpDoor
from .server import build_server, serve_http, serve_stdio
from .tools import MAX_WAIT, Options, RobotTools

__all__ = ["MAX_WAIT", "HttpDoor", "Options", "RobotTools", "build_server", "serve_http",
           "serve_stdio"]
