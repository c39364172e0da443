"""What every ``roslibpy-lite`` command shares: exit codes, output, types and values,
the connection, and the pieces of the argument parser."""

from __future__ import annotations

import argparse
import asyncio
import base64
import contextlib
import difflib
import json
import math
import re
import sys
import time
from collections.abc import Awaitable, Callable, Coroutine
from dataclasses import dataclass
from typing import Any, NoReturn, TextIO

from msgs.runtime import Message, UnknownTypeError, ValidationError, lookup
from rosbridge_core.protocol.names import absolute_name

from ..client import Client, connect
from ..exceptions import (
    ConnectError,
    NotAuthenticated,
    TLSError,
    UsageError,
)
from .format import ArgumentError, parse_values, to_yaml

DEFAULT_URL = "ws://127.0.0.1:9090"

EXIT_OK = 0
EXIT_ERROR = 1
EXIT_USAGE = 2
EXIT_CONNECT = 3
EXIT_NOT_FOUND = 4
EXIT_TIMEOUT = 5
EXIT_REMOTE = 6
EXIT_INTERRUPTED = 130

EXIT_CODES: dict[int, str] = {
    EXIT_OK: "success (also echo/hz/pub stopped with Ctrl+C)",
    EXIT_ERROR: "unexpected error",
    EXIT_USAGE: "bad arguments (command line, YAML/JSON values, message fields)",
    EXIT_CONNECT: "cannot connect to the bridge, or the connection was lost",
    EXIT_NOT_FOUND: "unknown topic, service, node or interface type",
    EXIT_TIMEOUT: "no answer in time",
    EXIT_REMOTE: "the service failed or the bridge refused the request",
    EXIT_INTERRUPTED: "interrupted (Ctrl+C) during a one-shot command",
}
"""Exit status -> meaning (also printed by ``--help``)."""

PRIMITIVES = frozenset({
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
    "int32", "uint32", "int64", "uint64", "string", "wstring",
})


class CliError(Exception):
    """A failure to report as one line on stderr with exit status ``code``."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(message)
        self.code = code
        self.message = message


# -- output ---------------------------------------------------------------------------------------


class Out:
    """Where a command writes (stdout unless a test says otherwise), flushed per record."""

    def __init__(self, stream: TextIO | None = None) -> None:
        self.stream = stream

    def line(self, text: str = "") -> None:
        """Write one line and flush (so pipes see records as they come)."""
        stream = self.stream or sys.stdout
        stream.write(text + "\n")
        stream.flush()

    def record(self, value: Any, as_json: bool, no_arr: bool = False) -> None:
        """One record: a JSON line, or a YAML document ended by ``---``."""
        if as_json:
            self.line(json.dumps(value, separators=(",", ":"), allow_nan=False,
                                 default=_json_default))
        else:
            self.line(to_yaml(value, no_arr=no_arr))
            self.line("---")


def _json_default(value: Any) -> Any:
    if isinstance(value, bytes | bytearray | memoryview):
        return list(bytes(value))
    raise TypeError(f"{type(value).__name__} is not JSON serializable")


def nan_to_none(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: nan_to_none(v) for k, v in value.items()}
    if isinstance(value, list):
        return [nan_to_none(v) for v in value]
    return value


# -- types and values -----------------------------------------------------------------------------


def type_parts(type_name: str, kind: str) -> tuple[str, str]:
    parts = type_name.split("/")
    if len(parts) == 2 and all(parts):
        return parts[0], parts[1]
    if len(parts) == 3 and all(parts) and parts[1] == kind:
        return parts[0], parts[2]
    article = "an" if kind == "action" else "a"
    raise CliError(EXIT_USAGE, f"{type_name!r} is not {article} {kind} type: expected "
                               f"'package/Name' or 'package/{kind}/Name'")


def local_class(type_name: str, kind: str) -> Any:
    """The generated class of a type, or None when this installation does not know it."""
    pkg, name = type_parts(type_name, kind)
    try:
        return lookup(f"{pkg}/{kind}/{name}")
    except UnknownTypeError:
        return None


def check_values(values: dict[str, Any], cls: type[Message] | None, what: str) -> dict[str, Any]:
    """Check ``values`` against ``cls`` (when known) and return their wire form."""
    if cls is None:
        return values
    try:
        return cls.from_json(values).to_json()
    except ValidationError as exc:
        raise CliError(EXIT_USAGE, f"bad {what} for {cls._type}: {exc}") from None


def cli_values(text: str | None, what: str) -> dict[str, Any]:
    try:
        return parse_values(text, what)
    except ArgumentError as exc:
        raise CliError(EXIT_USAGE, str(exc)) from None


_ARRAY = re.compile(r"^(?:sequence<([^,>]+)(?:,\s*\d+)?>|(.+)\[\d+\])$")


def for_display(value: Any, cls: type[Message] | None) -> Any:
    """A message's wire form as ``ros2 topic echo`` shows it, when its class is known here.

    Floats that the wire carries as null (NaN) become NaN again, and ``uint8``/``char``
    arrays (base64 on the wire) become lists of integers. Unknown types pass unchanged.
    """
    if cls is None or not isinstance(value, dict):
        return value
    shown = dict(value)
    for name, type_ in cls._fields_and_types.items():
        if name in shown:
            with contextlib.suppress(Exception):  # display only: never fail on odd data
                shown[name] = _show_field(shown[name], type_)
    return shown


def _show_field(value: Any, type_: str) -> Any:
    m = _ARRAY.match(type_)
    base = (m[1] or m[2]).strip() if m else type_
    if base in ("float", "double"):
        if m and isinstance(value, list):
            return [math.nan if v is None else v for v in value]
        return math.nan if value is None else value
    if m and base in ("uint8", "char") and isinstance(value, str):
        return list(base64.b64decode(value, validate=True))
    if "/" in base:
        pkg, _, name = base.partition("/")
        nested = lookup(f"{pkg}/msg/{name.rpartition('/')[2]}")
        if isinstance(nested, type) and issubclass(nested, Message):
            if m and isinstance(value, list):
                return [for_display(v, nested) for v in value]
            return for_display(value, nested)
    return value


# -- the connection ------------------------------------------------------------------------------


class CliSession:
    """A connected client plus the rosapi helpers the commands share."""

    def __init__(self, ros: Client, timeout: float) -> None:
        self.ros = ros
        self.timeout = timeout

    async def rosapi(self, name: str, args: dict[str, Any] | None = None) -> dict[str, Any]:
        """Call ``/rosapi/<name>`` and return its response."""
        return await self.ros.graph.rosapi(name, args, timeout=self.timeout)

    async def polled(self, name: str, args: dict[str, Any], key: str, wait: float,
                     missing: str, listing: tuple[str, str] | None = None) -> str:
        """``/rosapi/<name>``'s ``key``, asked again up to ``wait`` s while it is empty
        (graph discovery takes time); then ``CliError(EXIT_NOT_FOUND, missing)``, with the
        closest names of ``listing`` (a rosapi list service and its key) as "did you mean"."""
        deadline = time.monotonic() + wait
        while True:
            found = str((await self.rosapi(name, args)).get(key, ""))
            if found:
                return found
            if time.monotonic() >= deadline:
                raise CliError(EXIT_NOT_FOUND, missing + await self._did_you_mean(
                    next(iter(args.values()), ""), listing))
            await asyncio.sleep(0.1)

    async def _did_you_mean(self, name: str, listing: tuple[str, str] | None) -> str:
        if listing is None or not name:
            return ""
        known = [str(n) for n in (await self.rosapi(listing[0])).get(listing[1], [])]
        close = difflib.get_close_matches(name, known, n=3, cutoff=0.7)
        return f"; did you mean {' or '.join(close)}?" if close else ""

    async def topic_type(self, topic: str, wait: float) -> str:
        """The topic's type from the ROS graph; polls up to ``wait`` s."""
        return await self.polled("topic_type", {"topic": topic}, "type", wait,
                                 f"unknown topic {topic} (not in the ROS graph; give its TYPE "
                                 "to wait for it)", ("topics", "topics"))

    async def service_server(self, service: str, wait: float) -> str:
        """The type of ``service`` if a node serves it; polls up to ``wait`` s.

        Asks ``/rosapi/service_type``, which counts servers by service name: a
        service that only has clients (the graph lists those too) does not count,
        and nodes sharing a name (two bridges, say) do not hide each other.
        """
        return await self.polled("service_type", {"service": service}, "type", wait,
                                 f"unknown service {service} (no node serves it)",
                                 ("services", "services"))

    async def node_call(self, node: str, service: str, type_: str,
                        request: dict[str, Any] | None = None) -> dict[str, Any]:
        """Call the node's own service ``<node>/<service>`` (of type ``type_``)."""
        return await self.ros.call_service(f"{node}/{service}", type_, request or {},
                                           timeout=self.timeout)

    async def node(self, name: str, wait: float) -> str:
        """The fully qualified name of node ``name`` (``/`` added in front, as ros2 does),
        once the graph has it; polls up to ``wait`` s, then ``CliError(EXIT_NOT_FOUND)``."""
        full = absolute_name(name)
        deadline = time.monotonic() + wait
        while True:
            known = await self.ros.graph.node_names(timeout=self.timeout)
            if full in known:
                return full
            if time.monotonic() >= deadline:
                raise CliError(EXIT_NOT_FOUND, f"unknown node {full} (not in the ROS graph)"
                                               + await self._did_you_mean(full, ("nodes", "nodes")))
            await asyncio.sleep(0.1)  # graph discovery has no event to await here

    async def action_type(self, action: str, wait: float) -> str:
        """The type of the action ``action`` serves; polls up to ``wait`` s."""
        return await self.polled("action_type", {"action": action}, "type", wait,
                                 f"unknown action {action} (no action server serves it)",
                                 ("action_servers", "action_servers"))


Command = Callable[[argparse.Namespace, Out], Coroutine[Any, Any, int]]


def hidden(name: str) -> bool:
    """Whether a topic or service name is hidden, as ros2 sees it: a part of it starts with
    ``_`` (an action's ``/_action/...`` topics and services, say)."""
    return any(part.startswith("_") for part in name.split("/"))


def print_listing(out: Out, args: argparse.Namespace, pairs: list[tuple[str, str]]) -> int:
    """A ``list`` command's output: JSON objects with ``--json``, else a name a line
    (``name [type]`` with ``-t``); hidden names only with ``--include-hidden``."""
    if not getattr(args, "include_hidden", True):
        pairs = [(n, t) for n, t in pairs if not hidden(n)]
    if args.json:
        out.line(json.dumps([{"name": n, "type": t} for n, t in pairs]))
        return EXIT_OK
    for name, type_ in pairs:
        out.line(f"{name} [{type_}]" if args.show_types else name)
    return EXIT_OK


async def find_by_type(args: argparse.Namespace, out: Out, kind: str, type_: str) -> int:
    """``topic find`` / ``service find``: the names of that type (``/rosapi/<kind>s_for_type``),
    one a line, hidden ones only with ``--include-hidden-<kind>s``; ``-c``: how many."""
    type_parts(type_, "msg" if kind == "topic" else "srv")

    async def body(s: CliSession) -> int:
        plural = kind + "s"
        found = (await s.rosapi(f"{plural}_for_type", {"type": type_})).get(plural, [])
        names = sorted(str(n) for n in found
                       if getattr(args, f"include_hidden_{plural}") or not hidden(str(n)))
        if getattr(args, f"count_{plural}"):
            out.line(str(len(names)))
            return EXIT_OK
        for name in names:
            out.line(name)
        return EXIT_OK
    return await with_session(args, body)


async def with_session(args: argparse.Namespace, body: Callable[[CliSession], Awaitable[int]],
                       *, reconnect: bool = False) -> int:
    secure = args.url.startswith("wss://")
    try:
        ros = await connect(args.url, reconnect=reconnect, open_timeout=args.timeout,
                            token=args.token, ssl=args.cafile if secure else None)
    except NotAuthenticated as exc:
        text = str(exc)
        if "--token" not in text and "too many failed" not in text:
            text += " (set --token or $ROSLIBPY_LITE_TOKEN)"
        raise CliError(EXIT_CONNECT, text) from None
    except TLSError as exc:
        raise CliError(EXIT_CONNECT, str(exc)) from None  # its text names --cafile where it helps
    except ConnectError as exc:  # a server that answered "no" was running: no such question
        hint = "" if exc.refused is not None else (
            " (is the bridge running? set --url or $ROSLIBPY_LITE_URL)")
        raise CliError(EXIT_CONNECT, f"{exc}{hint}") from None
    except UsageError as exc:
        raise CliError(EXIT_USAGE, str(exc)) from None
    try:
        return await body(CliSession(ros, args.timeout))
    finally:
        await ros.close()


async def until(duration: float | None, work: Awaitable[None]) -> None:
    """Run ``work`` until it ends or ``duration`` seconds pass (None: no limit)."""
    with contextlib.suppress(TimeoutError):
        async with asyncio.timeout(duration):
            await work


async def print_line(args: argparse.Namespace, out: Out,
                     find: Callable[[CliSession], Awaitable[str]]) -> int:
    """Print the one line ``find`` answers in a session (``topic type``, ``action type``)."""
    async def body(s: CliSession) -> int:
        out.line(await find(s))
        return EXIT_OK
    return await with_session(args, body)


def lost(s: CliSession, what: str) -> CliError:
    return CliError(EXIT_CONNECT, f"{what}: the connection to {s.ros.url} was lost")


# -- the parser's pieces ---------------------------------------------------------------------------


def node_wait_parser() -> argparse.ArgumentParser:
    """The ``--wait`` of commands that name a node (ros2's ``--timeout``: ours is the
    bridge's)."""
    p = Parser(add_help=False)
    p.add_argument("--wait", type=float, default=1.0, metavar="SEC",
                   help="seconds to wait for the node to appear in the ROS graph (default 1)")
    return p


class Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise CliError(EXIT_USAGE, f"{message} (see '{self.prog} --help')")


@dataclass
class Kit:
    """What a noun module needs to add its commands to the parser."""

    common: argparse.ArgumentParser
    fmt: argparse.ArgumentParser
    wait: argparse.ArgumentParser
    swait: argparse.ArgumentParser

    def leaf(self, sub: Any, name: str, fn: Command, help_: str,
             *parents: argparse.ArgumentParser) -> argparse.ArgumentParser:
        """Add the command ``name`` running ``fn`` to the subparsers ``sub``."""
        p: argparse.ArgumentParser = sub.add_parser(
            name, help=help_, description=help_, parents=[self.common, *parents])
        p.set_defaults(func=fn)
        return p

    @staticmethod
    def group(groups: Any, name: str, help_: str, commands: str) -> Any:
        """Add the command group ``name`` (its ``commands``, comma-separated); its subparsers."""
        parser = groups.add_parser(name, help=help_)
        sub = parser.add_subparsers(dest="command", metavar=f"{{{commands}}}",
                                    parser_class=Parser)
        sub.required = True
        return sub

    def finding(self, sub: Any, fn: Command, kind: str, example: str) -> None:
        """Add ``find TYPE [-c] [--include-hidden-<kind>s]`` running ``fn``."""
        p = self.leaf(sub, "find", fn, f"list the {kind}s of a type")
        p.add_argument(f"{kind}_type", help=f"the {kind} type, e.g. {example}")
        p.add_argument("-c", f"--count-{kind}s", action="store_true",
                       help=f"print only how many {kind}s there are")
        p.add_argument(f"--include-hidden-{kind}s", action="store_true",
                       help=f"also hidden {kind}s (a part of the name starts with _)")

    def listing(self, sub: Any, fn: Command, help_: str, each: str, *, hidden: bool = False
                ) -> None:
        """Add ``list [-t]`` running ``fn`` (``-t``: show each ``each``'s type), with
        ``--include-hidden`` too when ``hidden``."""
        p = self.leaf(sub, "list", fn, help_, self.fmt)
        p.add_argument("-t", "--show-types", action="store_true", help=f"show each {each}'s type")
        if hidden:
            p.add_argument("--include-hidden", f"--include-hidden-{each}s", action="store_true",
                           help=f"also hidden {each}s (a part of the name starts with _, such as "
                                f"an action's /_action/ {each}s)")
