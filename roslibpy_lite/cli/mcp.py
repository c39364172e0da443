"""``roslibpy-lite mcp``: serve the robot to MCP clients (AI assistants and agents)."""

from __future__ import annotations

import argparse
from typing import Any

from .common import EXIT_OK, EXIT_USAGE, CliError, CliSession, Kit, Out, with_session


def _token(args: argparse.Namespace) -> None:
    """``--token-file``: the token is the file's first line (it never reaches a log)."""
    if args.token_file is None:
        return
    try:
        with open(args.token_file, encoding="utf-8") as f:
            token = f.readline().strip()
    except OSError as exc:
        raise CliError(EXIT_USAGE, f"--token-file {args.token_file}: {exc.strerror}") from None
    if not token:
        raise CliError(EXIT_USAGE, f"--token-file {args.token_file}: the file is empty")
    args.token = token


async def cmd_mcp(args: argparse.Namespace, out: Out) -> int:
    """``mcp``: an MCP server over stdio (or streamable HTTP with ``--http``)."""
    try:
        from ..mcp import Options, serve_http, serve_stdio
    except ImportError as exc:
        raise CliError(EXIT_USAGE, str(exc)) from None
    _token(args)
    options = Options(read_only=args.read_only, timeout=args.call_timeout,
                      image_size=args.image_size, confirm=args.confirm)

    async def body(s: CliSession) -> int:
        if args.http is not None:
            await serve_http(s.ros, options, host=args.host, port=args.http)
        else:
            await serve_stdio(s.ros, options)
        return EXIT_OK
    return await with_session(args, body, reconnect=True)


def add_parsers(groups: Any, kit: Kit) -> None:
    """Add ``mcp``."""
    p = kit.leaf(groups, "mcp", cmd_mcp,
                 "serve the robot's topics, services, actions and parameters to MCP clients "
                 "(AI assistants and agents), held to this token's role; needs the mcp extra")
    p.add_argument("--token-file", metavar="FILE",
                   help="read the token from FILE's first line (keeps it out of the "
                        "process list and the MCP client's config)")
    p.add_argument("--read-only", action="store_true",
                   help="offer no tool that changes anything (no publish, service call, goal "
                        "or parameter change), whatever the role allows")
    p.add_argument("--confirm", action="store_true",
                   help="ask the MCP client's user to confirm each change (publish, service "
                        "call, goal, cancel, parameter) before it is made (MCP elicitation)")
    p.add_argument("--call-timeout", type=float, default=10.0, metavar="SEC",
                   help="a tool call's default wait in seconds; a call may ask for up to "
                        "120 (default 10)")
    p.add_argument("--image-size", type=int, default=512, metavar="PX",
                   help="the longer side of an image a topic read returns (default 512)")
    p.add_argument("--http", type=int, metavar="PORT",
                   help="serve streamable HTTP on PORT (at /mcp) instead of stdio")
    p.add_argument("--host", default="127.0.0.1",
                   help="the address --http listens on (default 127.0.0.1)")
