"""``roslibpy-lite``: a ``ros2``-like command-line tool that needs no ROS, only a rosbridge.

Examples::

    roslibpy-lite topic list -t
    roslibpy-lite topic echo /example_counter --count 3
    roslibpy-lite topic pub /chatter std_msgs/msg/String "{data: hello}" --once
    roslibpy-lite topic hz /imu --duration 5
    roslibpy-lite service call /mult_floats mult_msgs/srv/MultFloats "{x: 2.5, y: 4.0}"
    roslibpy-lite node list
    roslibpy-lite interface show sensor_msgs/msg/Imu

The bridge is ``--url`` (default ``$ROSLIBPY_LITE_URL``, else
``ws://127.0.0.1:9090``); a bridge that requires a token gets ``--token``
(``$ROSLIBPY_LITE_TOKEN``), a ``wss://`` bridge with a private CA ``--cafile``
(``$ROSLIBPY_LITE_CAFILE``). Introspection goes through the bridge's
``/rosapi/*`` services. Errors print one line on stderr and exit with a
distinct status (see :data:`EXIT_CODES`).
"""

from __future__ import annotations

import argparse
import asyncio
import base64
import contextlib
import itertools
import json
import logging
import math
import os
import re
import statistics
import sys
import time
from collections import deque
from collections.abc import Awaitable, Callable, Coroutine, Sequence
from typing import Any, NoReturn, TextIO

from msgs.runtime import Message, Service, UnknownTypeError, ValidationError, lookup

from ._cli_format import ArgumentError, have_yaml, parse_values, to_yaml
from .client import Client, connect
from .exceptions import (
    ConnectError,
    ConnectionClosed,
    NotAuthenticated,
    RemoteError,
    RosTimeoutError,
    ServiceError,
    TLSError,
    UsageError,
)

__all__ = ["EXAMPLES", "EXIT_CODES", "build_parser", "main"]

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

_PRIMITIVES = frozenset({
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


def _nan_to_none(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _nan_to_none(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_nan_to_none(v) for v in value]
    return value


# -- types and values -----------------------------------------------------------------------------


def _type_parts(type_name: str, kind: str) -> tuple[str, str]:
    parts = type_name.split("/")
    if len(parts) == 2 and all(parts):
        return parts[0], parts[1]
    if len(parts) == 3 and all(parts) and parts[1] == kind:
        return parts[0], parts[2]
    raise CliError(EXIT_USAGE, f"{type_name!r} is not a {kind} type: expected "
                               f"'package/Name' or 'package/{kind}/Name'")


def _local_class(type_name: str, kind: str) -> Any:
    """The generated class of a type, or None when this installation does not know it."""
    pkg, name = _type_parts(type_name, kind)
    try:
        return lookup(f"{pkg}/{kind}/{name}")
    except UnknownTypeError:
        return None


def _check_values(values: dict[str, Any], cls: type[Message] | None, what: str) -> dict[str, Any]:
    """Check ``values`` against ``cls`` (when known) and return their wire form."""
    if cls is None:
        return values
    try:
        return cls.from_json(values).to_json()
    except ValidationError as exc:
        raise CliError(EXIT_USAGE, f"bad {what} for {cls._type}: {exc}") from None


def _values(text: str | None, what: str) -> dict[str, Any]:
    try:
        return parse_values(text, what)
    except ArgumentError as exc:
        raise CliError(EXIT_USAGE, str(exc)) from None


_ARRAY = re.compile(r"^(?:sequence<([^,>]+)(?:,\s*\d+)?>|(.+)\[\d+\])$")


def _for_display(value: Any, cls: type[Message] | None) -> Any:
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
                return [_for_display(v, nested) for v in value]
            return _for_display(value, nested)
    return value


# -- the connection ------------------------------------------------------------------------------


class Session:
    """A connected client plus the rosapi helpers the commands share."""

    def __init__(self, ros: Client, timeout: float) -> None:
        self.ros = ros
        self.timeout = timeout

    async def rosapi(self, name: str, args: dict[str, Any] | None = None) -> dict[str, Any]:
        """Call ``/rosapi/<name>`` and return its response."""
        return await self.ros.call_service(f"/rosapi/{name}", f"rosapi_msgs/srv/{_rosapi(name)}",
                                           args or {}, timeout=self.timeout)

    async def topic_type(self, topic: str, wait: float) -> str:
        """The topic's type from the ROS graph; polls up to ``wait`` s (discovery takes time)."""
        deadline = time.monotonic() + wait
        while True:
            found = str((await self.rosapi("topic_type", {"topic": topic})).get("type", ""))
            if found:
                return found
            if time.monotonic() >= deadline:
                raise CliError(EXIT_NOT_FOUND,
                               f"unknown topic {topic} (not in the ROS graph; give its TYPE "
                               "to wait for it)")
            await asyncio.sleep(0.1)

    async def service_server(self, service: str, wait: float) -> str:
        """The node serving ``service``; polls up to ``wait`` s (discovery takes time).

        Asks ``/rosapi/service_node``: a service that only has clients (the
        graph lists those too) does not count.
        """
        deadline = time.monotonic() + wait
        while True:
            node = str((await self.rosapi("service_node", {"service": service})).get("node", ""))
            if node:
                return node
            if time.monotonic() >= deadline:
                raise CliError(EXIT_NOT_FOUND, f"unknown service {service} (no node serves it)")
            await asyncio.sleep(0.1)


def _rosapi(name: str) -> str:
    special = {"get_time": "GetTime", "get_ros_version": "GetROSVersion",
               "action_servers": "GetActionServers"}
    return special.get(name, "".join(p.capitalize() for p in name.split("_")))


Command = Callable[[argparse.Namespace, Out], Coroutine[Any, Any, int]]


async def _with_session(args: argparse.Namespace, body: Callable[[Session], Awaitable[int]]) -> int:
    secure = args.url.startswith("wss://")
    try:
        ros = await connect(args.url, reconnect=False, open_timeout=args.timeout,
                            token=args.token, ssl=args.cafile if secure else None)
    except NotAuthenticated as exc:
        raise CliError(EXIT_CONNECT, f"{exc} (set --token or $ROSLIBPY_LITE_TOKEN)") from None
    except TLSError as exc:
        raise CliError(EXIT_CONNECT, f"{exc} (--cafile or $ROSLIBPY_LITE_CAFILE)") from None
    except ConnectError as exc:
        raise CliError(EXIT_CONNECT, f"{exc} (is the bridge running? set --url or "
                                     "$ROSLIBPY_LITE_URL)") from None
    except UsageError as exc:
        raise CliError(EXIT_USAGE, str(exc)) from None
    try:
        return await body(Session(ros, args.timeout))
    finally:
        await ros.close()


# -- topic ----------------------------------------------------------------------------------------


async def cmd_topic_list(args: argparse.Namespace, out: Out) -> int:
    """``topic list [-t]``."""
    async def body(s: Session) -> int:
        reply = await s.rosapi("topics")
        pairs = sorted(zip(reply.get("topics", []), reply.get("types", []), strict=False))
        if args.json:
            out.line(json.dumps([{"name": n, "type": t} for n, t in pairs]))
        for name, type_ in pairs if not args.json else ():
            out.line(f"{name} [{type_}]" if args.show_types else name)
        return EXIT_OK
    return await _with_session(args, body)


async def cmd_topic_type(args: argparse.Namespace, out: Out) -> int:
    """``topic type TOPIC``."""
    async def body(s: Session) -> int:
        out.line(await s.topic_type(args.topic, args.wait))
        return EXIT_OK
    return await _with_session(args, body)


async def cmd_topic_info(args: argparse.Namespace, out: Out) -> int:
    """``topic info TOPIC [-v]``: type and the nodes publishing and subscribing."""
    async def body(s: Session) -> int:
        type_ = await s.topic_type(args.topic, args.wait)
        pubs, subs = await asyncio.gather(
            s.rosapi("publishers", {"topic": args.topic}),
            s.rosapi("subscribers", {"topic": args.topic}),
        )
        publishers = list(pubs.get("publishers", []))
        subscribers = list(subs.get("subscribers", []))
        if args.json:
            out.line(json.dumps({"name": args.topic, "type": type_, "publishers": publishers,
                                 "subscribers": subscribers}))
            return EXIT_OK
        out.line(f"Type: {type_}")
        out.line(f"Publisher count: {len(publishers)}")
        if args.verbose:
            for node in publishers:
                out.line(f"  {node}")
        out.line(f"Subscription count: {len(subscribers)}")
        if args.verbose:
            for node in subscribers:
                out.line(f"  {node}")
        return EXIT_OK
    return await _with_session(args, body)


def _stop_after(args: argparse.Namespace) -> float | None:
    if args.duration is not None and args.duration <= 0:
        raise CliError(EXIT_USAGE, f"--duration must be > 0, got {args.duration}")
    if getattr(args, "count", None) is not None and args.count < 1:
        raise CliError(EXIT_USAGE, f"--count must be >= 1, got {args.count}")
    if args.type:
        _type_parts(args.type, "msg")
    duration: float | None = args.duration
    return duration


async def _resolve_topic_type(s: Session, args: argparse.Namespace) -> str:
    if args.type:
        _type_parts(args.type, "msg")
        return str(args.type)
    return await s.topic_type(args.topic, args.wait)


async def _until(duration: float | None, work: Awaitable[None]) -> None:
    """Run ``work`` until it ends or ``duration`` seconds pass (None: no limit)."""
    with contextlib.suppress(TimeoutError):
        async with asyncio.timeout(duration):
            await work


def _lost(s: Session, what: str) -> CliError:
    return CliError(EXIT_CONNECT, f"{what}: the connection to {s.ros.url} was lost")


async def cmd_topic_echo(args: argparse.Namespace, out: Out) -> int:
    """``topic echo TOPIC [TYPE]``: print messages until Ctrl+C, --count or --duration."""
    duration = _stop_after(args)

    async def body(s: Session) -> int:
        type_ = await _resolve_topic_type(s, args)
        cls = None if args.json else _local_class(type_, "msg")
        seen = 0

        async def work() -> None:
            nonlocal seen
            async with s.ros.subscribe(args.topic, type_, throttle_rate=args.throttle_ms,
                                       queue_length=args.queue_length) as sub:
                async for msg in sub:
                    out.record(_for_display(msg, cls), args.json, args.no_arr)
                    seen += 1
                    if args.count is not None and seen >= args.count:
                        return
            raise _lost(s, f"echo {args.topic}")

        await _until(duration, work())
        return EXIT_OK
    return await _with_session(args, body)


class RateStats:
    """Arrival times of messages, and ros2-style rate statistics over a window."""

    def __init__(self, window: int) -> None:
        self.times: deque[float] = deque(maxlen=window + 1)
        self.total = 0

    def add(self, t: float) -> None:
        """Record one arrival at time ``t`` (seconds)."""
        self.times.append(t)
        self.total += 1

    def report(self) -> dict[str, Any] | None:
        """Rate, min/max/std dev of the gaps and window size; None before two messages."""
        if len(self.times) < 2:
            return None
        ts = list(self.times)
        gaps = [b - a for a, b in itertools.pairwise(ts)]
        mean = sum(gaps) / len(gaps)
        return {
            "rate": 1.0 / mean if mean > 0 else math.inf,
            "min": min(gaps),
            "max": max(gaps),
            "std_dev": statistics.pstdev(gaps),
            "window": len(gaps),
        }


async def cmd_topic_hz(args: argparse.Namespace, out: Out) -> int:
    """``topic hz TOPIC [TYPE]``: print the rate every second until Ctrl+C/--count/--duration."""
    duration = _stop_after(args)
    if args.window < 1:
        raise CliError(EXIT_USAGE, f"--window must be >= 1, got {args.window}")

    async def body(s: Session) -> int:
        type_ = await _resolve_topic_type(s, args)
        stats = RateStats(args.window)
        loop = asyncio.get_running_loop()
        last_total = -1

        def show() -> None:
            nonlocal last_total
            report = stats.report()
            if report is None or stats.total == last_total:
                if not args.json:
                    out.line("no new messages")
                return
            last_total = stats.total
            if args.json:
                out.line(json.dumps(_nan_to_none(report)))
            else:
                out.line(f"average rate: {report['rate']:.3f}")
                out.line(f"\tmin: {report['min']:.3f}s max: {report['max']:.3f}s "
                         f"std dev: {report['std_dev']:.5f}s window: {report['window']}")

        async def work() -> None:
            async with s.ros.subscribe(args.topic, type_, queue_length=args.queue_length,
                                       buffer_size=10_000) as sub:
                next_report = loop.time() + 1.0
                while True:
                    try:
                        async with asyncio.timeout_at(next_report):
                            await sub.__anext__()
                    except TimeoutError:
                        show()
                        next_report += 1.0
                        continue
                    except StopAsyncIteration:
                        raise _lost(s, f"hz {args.topic}") from None
                    stats.add(loop.time())
                    if args.count is not None and stats.total >= args.count:
                        return

        try:
            await _until(duration, work())
        finally:
            if stats.total != last_total and stats.report() is not None:
                show()
        return EXIT_OK
    return await _with_session(args, body)


async def cmd_topic_pub(args: argparse.Namespace, out: Out) -> int:
    """``topic pub TOPIC TYPE [VALUES]``: publish once, N times, or at a rate until Ctrl+C."""
    _type_parts(args.type, "msg")
    cls = _local_class(args.type, "msg")
    values = _check_values(_values(args.values, "VALUES"), cls, "VALUES")
    if args.rate <= 0:
        raise CliError(EXIT_USAGE, f"--rate must be > 0, got {args.rate}")
    times = 1 if args.once else args.times
    if times is not None and times < 1:
        raise CliError(EXIT_USAGE, f"--times must be >= 1, got {times}")
    wait_subs = args.wait_matching_subscriptions
    if wait_subs is None:
        wait_subs = 1 if times is not None else 0
    if wait_subs < 0:
        raise CliError(EXIT_USAGE, "--wait-matching-subscriptions must be >= 0")

    async def body(s: Session) -> int:
        pub = await s.ros.advertise(args.topic, args.type, latch=args.latch)
        # A rosapi round trip: the bridge has handled our advertise when it answers.
        subscribers = (await s.rosapi("subscribers", {"topic": args.topic})).get("subscribers", [])
        if pub.error is not None:
            raise CliError(EXIT_REMOTE, f"the bridge refused to advertise {args.topic}: "
                                        f"{pub.error}")
        if len(subscribers) < wait_subs:
            if not args.quiet:
                print(f"Waiting for at least {wait_subs} matching subscription(s)...",
                      file=sys.stderr, flush=True)
            while len(subscribers) < wait_subs:
                await asyncio.sleep(0.1)  # ROS graph discovery has no event to await
                subscribers = (await s.rosapi("subscribers", {"topic": args.topic})).get(
                    "subscribers", [])
        loop = asyncio.get_running_loop()
        start = loop.time()
        n = 0
        while times is None or n < times:
            if n:
                delay = start + n / args.rate - loop.time()
                if delay > 0:
                    await asyncio.sleep(delay)
            await pub.publish(values)
            n += 1
            if not args.quiet:
                out.line(f"publishing #{n}: {json.dumps(values, separators=(', ', ': '))}")
        await pub  # every message handed to the connection before closing
        if pub.error is not None:
            raise CliError(EXIT_REMOTE, f"publish to {args.topic}: {pub.error}")
        return EXIT_OK
    return await _with_session(args, body)


# -- service ---------------------------------------------------------------------------------------


async def cmd_service_list(args: argparse.Namespace, out: Out) -> int:
    """``service list [-t]``."""
    async def body(s: Session) -> int:
        names = sorted((await s.rosapi("services")).get("services", []))
        types: list[str] = []
        if args.show_types or args.json:
            replies = await asyncio.gather(*(s.rosapi("service_type", {"service": n})
                                             for n in names))
            types = [str(r.get("type", "")) for r in replies]
        if args.json:
            out.line(json.dumps([{"name": n, "type": t} for n, t in zip(names, types,
                                                                         strict=True)]))
            return EXIT_OK
        for i, name in enumerate(names):
            out.line(f"{name} [{types[i]}]" if args.show_types else name)
        return EXIT_OK
    return await _with_session(args, body)


async def cmd_service_type(args: argparse.Namespace, out: Out) -> int:
    """``service type SERVICE``."""
    async def body(s: Session) -> int:
        await s.service_server(args.service, args.wait)
        found = str((await s.rosapi("service_type", {"service": args.service})).get("type", ""))
        if not found:
            raise CliError(EXIT_NOT_FOUND, f"unknown service {args.service}")
        out.line(found)
        return EXIT_OK
    return await _with_session(args, body)


async def cmd_service_call(args: argparse.Namespace, out: Out) -> int:
    """``service call SERVICE TYPE [VALUES]``: print the response."""
    _type_parts(args.type, "srv")
    srv = _local_class(args.type, "srv")
    request_cls = srv.Request if isinstance(srv, type) and issubclass(srv, Service) else None
    values = _check_values(_values(args.values, "VALUES"), request_cls, "VALUES")
    if args.call_timeout is not None and args.call_timeout <= 0:
        raise CliError(EXIT_USAGE, f"--call-timeout must be > 0, got {args.call_timeout}")

    async def body(s: Session) -> int:
        await s.service_server(args.service, args.wait)
        try:
            response = await s.ros.call_service(args.service, args.type, values,
                                                timeout=args.call_timeout)
        except ServiceError as exc:
            raise CliError(EXIT_REMOTE, str(exc)) from None
        if args.json:
            out.line(json.dumps(response, separators=(",", ":")))
        else:
            out.line(to_yaml(response))
        return EXIT_OK
    return await _with_session(args, body)


# -- node -----------------------------------------------------------------------------------------


async def cmd_node_list(args: argparse.Namespace, out: Out) -> int:
    """``node list``."""
    async def body(s: Session) -> int:
        names = sorted((await s.rosapi("nodes")).get("nodes", []))
        if args.json:
            out.line(json.dumps(names))
        for name in names if not args.json else ():
            out.line(name)
        return EXIT_OK
    return await _with_session(args, body)


async def cmd_node_info(args: argparse.Namespace, out: Out) -> int:
    """``node info NODE``: what a node publishes, subscribes to and serves."""
    async def body(s: Session) -> int:
        name = args.node if args.node.startswith("/") else "/" + args.node
        if name not in (await s.rosapi("nodes")).get("nodes", []):
            raise CliError(EXIT_NOT_FOUND, f"unknown node {name}")
        details = await s.rosapi("node_details", {"node": name})
        if args.json:
            out.line(json.dumps({"name": name, **details}))
            return EXIT_OK
        out.line(name)
        for title, key in (("Subscribers", "subscribing"), ("Publishers", "publishing"),
                           ("Service Servers", "services")):
            out.line(f"  {title}:")
            for item in details.get(key, []):
                out.line(f"    {item}")
        return EXIT_OK
    return await _with_session(args, body)


# -- interface ------------------------------------------------------------------------------------


def _interface_class(type_name: str) -> Any:
    try:
        return lookup(type_name)
    except UnknownTypeError as exc:
        raise CliError(EXIT_NOT_FOUND, f"{exc} (see 'roslibpy-lite interface list')") from None


def _field_type(line: str, package: str) -> str | None:
    """The message type a definition line's field refers to (None for primitives/constants)."""
    body = line.split("#", 1)[0].strip()
    if not body or body == "---":
        return None
    parts = body.split()
    if len(parts) < 2 or "=" in parts[1] or (len(parts) > 2 and parts[2].startswith("=")):
        return None  # not a field, or a constant
    base = parts[0].split("[", 1)[0].split("<", 1)[0]
    if base in _PRIMITIVES:
        return None
    if "/" in base:
        pkg, _, name = base.partition("/")
        return f"{pkg}/msg/{name.rpartition('/')[2]}"
    if base == "Header":
        return "std_msgs/msg/Header"
    return f"{package}/msg/{base}"


def _show(definition: str, package: str, depth: int, lines: list[str]) -> None:
    pad = "\t" * depth
    for line in definition.rstrip("\n").split("\n"):
        lines.append(pad + line if line else "")
        nested = _field_type(line, package)
        if nested is None:
            continue
        try:
            cls = lookup(nested)
        except UnknownTypeError:
            continue
        _show(cls._definition, nested.split("/", 1)[0], depth + 1, lines)


async def cmd_interface_show(args: argparse.Namespace, out: Out) -> int:
    """``interface show TYPE``: the definition, nested types expanded (from msgs, no bridge)."""
    cls = _interface_class(args.type)
    lines: list[str] = []
    if args.raw:
        lines = cls._definition.rstrip("\n").split("\n")
    else:
        _show(cls._definition, cls._type.split("/", 1)[0], 0, lines)
    for line in lines:
        out.line(line)
    return EXIT_OK


async def cmd_interface_list(args: argparse.Namespace, out: Out) -> int:
    """``interface list [PACKAGE]``: the types this installation knows."""
    from msgs.runtime import available_packages, available_types

    if args.package is not None and args.package not in available_packages():
        raise CliError(EXIT_NOT_FOUND, f"unknown interface package {args.package}")
    for name in available_types(args.package):
        out.line(name)
    return EXIT_OK


# -- the command line ----------------------------------------------------------------------------


EXAMPLES: tuple[str, ...] = (
    "topic list -t",
    "topic echo /example_counter --count 3",
    'topic pub /chatter std_msgs/msg/String "{data: hello}" --once',
    "topic hz /imu --duration 3",
    'service call /mult_floats mult_msgs/srv/MultFloats "{x: 2.5, y: 4.0}"',
    "node list",
    "interface show sensor_msgs/msg/Imu",
)
"""The examples ``--help`` shows (tests/cli/test_examples.py runs each against the demo's parts)."""


def _epilog() -> str:
    codes = "\n".join(f"  {code:<4} {text}" for code, text in EXIT_CODES.items())
    yaml_note = ("VALUES are YAML or JSON" if have_yaml()
                 else "VALUES are JSON (install 'roslibpy-lite[cli]' for YAML)")
    examples = "\n".join(f"  roslibpy-lite {e}" for e in EXAMPLES)
    return f"examples:\n{examples}\n\n{yaml_note}.\n\nexit status:\n{codes}"


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise CliError(EXIT_USAGE, f"{message} (see '{self.prog} --help')")


class _RootParser(_Parser):
    """Fills ``--url``/``--timeout`` defaults after parsing, so the options may stand
    before or after the subcommand (argparse would let a subcommand's defaults
    overwrite a value given before it)."""

    def parse_known_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> tuple[argparse.Namespace, list[str]]:
        parsed, rest = super().parse_known_args(args, namespace)
        if getattr(parsed, "url", None) is None:
            parsed.url = os.environ.get("ROSLIBPY_LITE_URL") or DEFAULT_URL
        if getattr(parsed, "timeout", None) is None:
            parsed.timeout = 5.0
        if getattr(parsed, "token", None) is None:
            parsed.token = os.environ.get("ROSLIBPY_LITE_TOKEN") or None
        if getattr(parsed, "cafile", None) is None:
            parsed.cafile = os.environ.get("ROSLIBPY_LITE_CAFILE") or None
        return parsed, rest


def build_parser() -> argparse.ArgumentParser:
    """The argument parser (exposed for tests and documentation)."""
    common = _Parser(add_help=False)
    common.add_argument("--url", default=argparse.SUPPRESS,
                        help="the bridge (default $ROSLIBPY_LITE_URL or " + DEFAULT_URL + ")")
    common.add_argument("--timeout", type=float, default=argparse.SUPPRESS,
                        help="seconds to wait for the bridge: connecting and each "
                             "introspection call (default 5)")
    common.add_argument("--token", default=argparse.SUPPRESS,
                        help="token for a bridge that requires one (default "
                             "$ROSLIBPY_LITE_TOKEN); sent as an Authorization header")
    common.add_argument("--cafile", default=argparse.SUPPRESS,
                        help="CA file (PEM) that signed a wss:// bridge's certificate "
                             "(default $ROSLIBPY_LITE_CAFILE, else the system's CAs)")
    fmt = _Parser(add_help=False)
    fmt.add_argument("--json", action="store_true", help="JSON output (one object per line)")
    wait = _Parser(add_help=False)
    wait.add_argument("--wait", type=float, default=2.0, metavar="SEC",
                      help="seconds to wait for an unknown topic to appear in the ROS graph "
                           "(default 2)")
    swait = _Parser(add_help=False)
    swait.add_argument("--wait", type=float, default=2.0, metavar="SEC",
                       help="seconds to wait for the service to appear in the ROS graph "
                            "(default 2)")

    root = _RootParser(
        prog="roslibpy-lite",
        description="Talk to a ROS 2 robot through a rosbridge server; no ROS needed here.",
        epilog=_epilog(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common],
    )
    groups = root.add_subparsers(dest="group", metavar="{topic,service,node,interface}",
                                 parser_class=_Parser)
    groups.required = True

    def leaf(sub: Any, name: str, fn: Command, help_: str, *parents: argparse.ArgumentParser,
             ) -> argparse.ArgumentParser:
        p: argparse.ArgumentParser = sub.add_parser(
            name, help=help_, description=help_, parents=[common, *parents])
        p.set_defaults(func=fn)
        return p

    # topic
    topic = groups.add_parser("topic", help="topics: list, type, info, echo, pub, hz")
    tsub = topic.add_subparsers(dest="command", metavar="{list,type,info,echo,pub,hz}",
                                parser_class=_Parser)
    tsub.required = True
    p = leaf(tsub, "list", cmd_topic_list, "list the topics in the ROS graph", fmt)
    p.add_argument("-t", "--show-types", action="store_true", help="show each topic's type")
    p = leaf(tsub, "type", cmd_topic_type, "print a topic's type", wait)
    p.add_argument("topic")
    p = leaf(tsub, "info", cmd_topic_info, "a topic's type, publishers and subscribers",
             fmt, wait)
    p.add_argument("topic")
    p.add_argument("-v", "--verbose", action="store_true", help="list the nodes")
    p = leaf(tsub, "echo", cmd_topic_echo,
             "print messages (YAML documents separated by ---, or --json lines)", fmt, wait)
    p.add_argument("topic")
    p.add_argument("type", nargs="?", help="message type (default: looked up in the graph)")
    p.add_argument("--count", "-n", type=int, help="stop after this many messages")
    p.add_argument("--duration", type=float, help="stop after this many seconds")
    p.add_argument("--no-arr", action="store_true", help="print sequences as their length")
    p.add_argument("--throttle-ms", type=int, default=0, help="minimum ms between messages")
    p.add_argument("--queue-length", type=int, default=0, help="the bridge's queue for us")
    p = leaf(tsub, "pub", cmd_topic_pub, "publish a message", )
    p.add_argument("topic")
    p.add_argument("type", help="message type, e.g. std_msgs/msg/String")
    p.add_argument("values", nargs="?", default=None,
                   help="the message in YAML or JSON, e.g. \"{data: hello}\" (default: {})")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("-1", "--once", action="store_true", help="publish one message and exit")
    mode.add_argument("-t", "--times", type=int, help="publish this many messages and exit")
    p.add_argument("-r", "--rate", type=float, default=1.0, help="messages per second (default 1)")
    p.add_argument("-w", "--wait-matching-subscriptions", type=int, default=None, metavar="N",
                   help="first wait for N subscribers (default 1 with --once/--times, else 0)")
    p.add_argument("--latch", action="store_true", help="late subscribers get the last message")
    p.add_argument("-q", "--quiet", action="store_true", help="do not print what is published")
    p = leaf(tsub, "hz", cmd_topic_hz, "print the publishing rate every second", fmt, wait)
    p.add_argument("topic")
    p.add_argument("type", nargs="?", help="message type (default: looked up in the graph)")
    p.add_argument("--window", "-w", type=int, default=10000,
                   help="messages the statistics cover (default 10000)")
    p.add_argument("--count", "-n", type=int, help="stop after this many messages")
    p.add_argument("--duration", type=float, help="stop after this many seconds")
    p.add_argument("--queue-length", type=int, default=0, help="the bridge's queue for us")

    # service
    service = groups.add_parser("service", help="services: list, type, call")
    ssub = service.add_subparsers(dest="command", metavar="{list,type,call}",
                                  parser_class=_Parser)
    ssub.required = True
    p = leaf(ssub, "list", cmd_service_list, "list the services", fmt)
    p.add_argument("-t", "--show-types", action="store_true", help="show each service's type")
    p = leaf(ssub, "type", cmd_service_type, "print a service's type", swait)
    p.add_argument("service")
    p = leaf(ssub, "call", cmd_service_call, "call a service and print the response", fmt,
             swait)
    p.add_argument("service")
    p.add_argument("type", help="service type, e.g. mult_msgs/srv/MultFloats")
    p.add_argument("values", nargs="?", default=None,
                   help="the request in YAML or JSON, e.g. \"{x: 2.5, y: 4.0}\" (default: {})")
    p.add_argument("--call-timeout", type=float, default=10.0,
                   help="seconds to wait for the response (default 10)")

    # node
    node = groups.add_parser("node", help="nodes: list, info")
    nsub = node.add_subparsers(dest="command", metavar="{list,info}", parser_class=_Parser)
    nsub.required = True
    leaf(nsub, "list", cmd_node_list, "list the nodes", fmt)
    p = leaf(nsub, "info", cmd_node_info, "what a node publishes, subscribes to and serves", fmt)
    p.add_argument("node")

    # interface
    interface = groups.add_parser("interface", help="interface types: show, list (no bridge)")
    isub = interface.add_subparsers(dest="command", metavar="{show,list}", parser_class=_Parser)
    isub.required = True
    p = leaf(isub, "show", cmd_interface_show, "print an interface definition")
    p.add_argument("type", help="e.g. sensor_msgs/msg/Imu, mult_msgs/srv/MultFloats")
    p.add_argument("--raw", action="store_true", help="do not expand nested types")
    p = leaf(isub, "list", cmd_interface_list, "list the known interface types")
    p.add_argument("package", nargs="?", help="only this package")
    return root


_client_log = logging.getLogger("roslibpy_lite")

_STREAMING = {cmd_topic_echo, cmd_topic_hz, cmd_topic_pub}


def _fail(code: int, message: str) -> int:
    print(f"roslibpy-lite: {message}", file=sys.stderr, flush=True)
    return code


def main(argv: Sequence[str] | None = None, *, stdout: TextIO | None = None) -> int:
    """Run the command line ``argv`` (default ``sys.argv[1:]``); returns the exit status."""
    try:
        args = build_parser().parse_args(argv)
    except CliError as exc:
        return _fail(exc.code, exc.message)
    except SystemExit as exc:  # --help
        return exc.code if isinstance(exc.code, int) else EXIT_OK
    if args.timeout <= 0:
        return _fail(EXIT_USAGE, f"--timeout must be > 0, got {args.timeout}")
    out = Out(stdout)
    func: Command = args.func
    if not _client_log.handlers:  # errors are reported here, once; no stray log lines
        _client_log.addHandler(logging.NullHandler())
    try:
        return asyncio.run(func(args, out))
    except KeyboardInterrupt:
        return EXIT_OK if func in _STREAMING else EXIT_INTERRUPTED
    except CliError as exc:
        return _fail(exc.code, exc.message)
    except RosTimeoutError as exc:
        return _fail(EXIT_TIMEOUT, str(exc))
    except ConnectError as exc:
        return _fail(EXIT_CONNECT, str(exc))
    except ConnectionClosed as exc:
        return _fail(EXIT_CONNECT, f"connection lost: {exc}")
    except RemoteError as exc:
        return _fail(EXIT_REMOTE, str(exc))
    except UsageError as exc:
        return _fail(EXIT_USAGE, str(exc))
    except BrokenPipeError:
        # The reader went away (``| head``): stop quietly, as other tools do.
        with contextlib.suppress(OSError):
            sys.stdout = open(os.devnull, "w")  # noqa: SIM115 - keep interpreter exit quiet
        return EXIT_OK
    except Exception as exc:
        return _fail(EXIT_ERROR, f"unexpected error: {type(exc).__name__}: {exc}")


if __name__ == "__main__":
    sys.exit(main())
