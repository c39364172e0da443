"""``roslibpy-lite mcp``: serve the robot to MCP clients (AI assistants and agents)."""

from __future__ import annotations

import argparse
import asyncio
import logging
import sys
from typing import Any

from .common import (
    EXIT_CONNECT,
    EXIT_OK,
    EXIT_USAGE,
    CliError,
    CliSession,
    Kit,
    Out,
    with_session,
)

_log = logging.getLogger("roslibpy_lite.mcp")


def _first_line(path: str, flag: str) -> str:
    """A secret: the first line of ``path`` (it never reaches a log or an error)."""
    try:
        with open(path, encoding="utf-8") as f:
            secret = f.readline().strip()
    except OSError as exc:
        raise CliError(EXIT_USAGE, f"{flag} {path}: {exc.strerror}") from None
    if not secret:
        raise CliError(EXIT_USAGE, f"{flag} {path}: the file is empty")
    return secret


def _door(args: argparse.Namespace) -> Any:
    """The HTTP door the options describe (refused here, before the robot is dialled)."""
    from ..mcp import HttpDoor

    http_only = [flag for flag, given in (
        ("--http-token-file", args.http_token_file), ("--http-certfile", args.http_certfile),
        ("--http-keyfile", args.http_keyfile), ("--no-http-auth", args.no_http_auth),
        ("--insecure", args.insecure), ("--allowed-hosts", args.allowed_hosts),
        ("--allowed-origins", args.allowed_origins)) if given]
    if args.http is None:
        if http_only:
            raise CliError(EXIT_USAGE, f"{', '.join(http_only)} only apply with --http PORT")
        return None
    token = (None if args.http_token_file is None
             else _first_line(args.http_token_file, "--http-token-file"))
    door = HttpDoor(host=args.host, port=args.http, token=token, certfile=args.http_certfile,
                    keyfile=args.http_keyfile, allowed_hosts=_listed(args.allowed_hosts),
                    allowed_origins=_listed(args.allowed_origins), insecure=args.insecure,
                    no_auth=args.no_http_auth)
    refusal = door.refusal()
    if refusal is not None:
        raise CliError(EXIT_USAGE, refusal)
    return door


def _listed(text: str | None) -> tuple[str, ...]:
    return tuple(x.strip() for x in (text or "").split(",") if x.strip())


def _log_to_stderr() -> None:
    """The MCP server's own log (warnings, and each HTTP request) on stderr: stdout is the
    protocol's under stdio."""
    logger = logging.getLogger("roslibpy_lite.mcp")
    if not logger.handlers:
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
        logger.addHandler(handler)
        logger.setLevel(logging.INFO)


_UNREACHED = ("is the bridge running?", "answered HTTP 404")
"""In a connection error's text: nothing answers yet, or the relay has no such robot yet."""


def _token_source(args: argparse.Namespace, exc: CliError) -> CliError:
    """``exc`` naming the token source this server used (its --token-file, not the
    generic --token/$ROSLIBPY_LITE_TOKEN hint)."""
    generic = "(set --token or $ROSLIBPY_LITE_TOKEN)"
    if args.token_file is None or generic not in exc.message:
        return exc
    return CliError(exc.code, exc.message.replace(
        generic, f"(the token read from --token-file {args.token_file})"))


async def cmd_mcp(args: argparse.Namespace, out: Out) -> int:
    """``mcp``: an MCP server over stdio (or streamable HTTP with ``--http``). A robot not
    reachable at start (its bridge not up, not on its relay yet) is waited for, up to
    ``--start-wait`` seconds, with a line in the log at each try."""
    try:
        from ..mcp import Options, serve_http, serve_stdio
    except ImportError as exc:
        raise CliError(EXIT_USAGE, str(exc)) from None
    if args.token_file is not None:
        args.token = _first_line(args.token_file, "--token-file")
    door = _door(args)
    _log_to_stderr()
    options = Options(read_only=args.read_only, timeout=args.call_timeout,
                      image_size=args.image_size, confirm=args.confirm)
    started = False

    async def body(s: CliSession) -> int:
        nonlocal started
        started = True
        if door is not None:
            await serve_http(s.ros, options, door)
        else:
            await serve_stdio(s.ros, options)
        return EXIT_OK

    loop = asyncio.get_running_loop()
    until, delay = loop.time() + args.start_wait, 1.0
    while True:
        try:
            return await with_session(args, body, reconnect=True)
        except CliError as exc:
            left = until - loop.time()
            if (started or exc.code != EXIT_CONNECT or left <= 0
                    or not any(u in exc.message for u in _UNREACHED)):
                raise _token_source(args, exc) from None
            wait = min(delay, left)
            _log.warning("the robot is not reachable yet (%s); trying again in %.0f s "
                         "(for %.0f s more: --start-wait)", exc.message, wait, left)
            await asyncio.sleep(wait)
            delay = min(delay * 2, 15.0)


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
    p.add_argument("--start-wait", type=float, default=120.0, metavar="SEC",
                   help="at start, wait up to SEC seconds for a robot not reachable yet (its "
                        "bridge not up, not on its relay yet), saying so in the log at each "
                        "try (default 120; 0: fail at once)")
    p.add_argument("--http", type=int, metavar="PORT",
                   help="serve streamable HTTP on PORT (at /mcp) instead of stdio")
    p.add_argument("--host", default="127.0.0.1",
                   help="the address --http listens on (default 127.0.0.1; another address "
                        "needs --http-certfile and --http-token-file, or --insecure)")
    g = p.add_argument_group("the HTTP door (with --http; see docs/guides/mcp.md)")
    g.add_argument("--http-token-file", metavar="FILE",
                   help="require this bearer token (FILE's first line, at least 24 "
                        "characters) of every HTTP client: 'Authorization: Bearer <token>'")
    g.add_argument("--no-http-auth", action="store_true",
                   help="serve a loopback --host without a token (every local user may act "
                        "with the robot token's role; a warning is logged at every start)")
    g.add_argument("--http-certfile", metavar="FILE",
                   help="PEM certificate chain: serve HTTPS")
    g.add_argument("--http-keyfile", metavar="FILE",
                   help="PEM private key of --http-certfile (if not in it)")
    g.add_argument("--insecure", action="store_true",
                   help="allow a non-loopback --host without TLS or a token (anyone who "
                        "reaches the port acts as the agent; a warning at every start)")
    g.add_argument("--allowed-hosts", metavar="NAMES",
                   help="comma-separated Host header values to accept besides loopback names "
                        "and --host, e.g. robot-pc.example.com (other Hosts: 421)")
    g.add_argument("--allowed-origins", metavar="ORIGINS",
                   help="comma-separated browser origins to accept, e.g. "
                        "https://ui.example.com (clients sending no Origin always may)")
