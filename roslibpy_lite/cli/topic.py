"""``roslibpy-lite topic list|type|find|info|echo|hz|pub`` (``bw`` and ``delay``:
:mod:`.topic_stats`)."""

from __future__ import annotations

import argparse
import asyncio
import itertools
import json
import math
import statistics
import sys
from collections import deque
from typing import Any

from ..exceptions import RemoteError
from . import topic_stats
from .common import (
    EXIT_OK,
    EXIT_REMOTE,
    EXIT_USAGE,
    CliError,
    CliSession,
    Kit,
    Out,
    check_values,
    cli_values,
    find_by_type,
    for_display,
    local_class,
    lost,
    nan_to_none,
    print_line,
    print_listing,
    type_parts,
    until,
    with_session,
)


async def cmd_topic_list(args: argparse.Namespace, out: Out) -> int:
    """``topic list [-t]``."""
    async def body(s: CliSession) -> int:
        topics = await s.ros.graph.topics(timeout=s.timeout)
        return print_listing(out, args, [(t.name, t.type) for t in topics])
    return await with_session(args, body)


async def cmd_topic_type(args: argparse.Namespace, out: Out) -> int:
    """``topic type TOPIC``."""
    return await print_line(args, out, lambda s: s.topic_type(args.topic, args.wait))


async def cmd_topic_find(args: argparse.Namespace, out: Out) -> int:
    """``topic find TYPE [-c]``: the topics of that type."""
    return await find_by_type(args, out, "topic", args.topic_type)


async def cmd_topic_info(args: argparse.Namespace, out: Out) -> int:
    """``topic info TOPIC [-v]``: type and the nodes publishing and subscribing."""
    async def body(s: CliSession) -> int:
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
    return await with_session(args, body)


def _stop_after(args: argparse.Namespace) -> float | None:
    if args.duration is not None and args.duration <= 0:
        raise CliError(EXIT_USAGE, f"--duration must be > 0, got {args.duration}")
    if getattr(args, "count", None) is not None and args.count < 1:
        raise CliError(EXIT_USAGE, f"--count must be >= 1, got {args.count}")
    if args.type:
        type_parts(args.type, "msg")
    duration: float | None = args.duration
    return duration


async def _resolve_topic_type(s: CliSession, args: argparse.Namespace) -> str:
    if args.type:
        type_parts(args.type, "msg")
        return str(args.type)
    return await s.topic_type(args.topic, args.wait)




async def cmd_topic_echo(args: argparse.Namespace, out: Out) -> int:
    """``topic echo TOPIC [TYPE]``: print messages until Ctrl+C, --count, --once or --duration.

    ``--field a.b`` prints only that field of each message, as ``ros2 topic echo`` does.
    """
    if args.once:
        args.count = 1
    duration = _stop_after(args)

    async def body(s: CliSession) -> int:
        type_ = await _resolve_topic_type(s, args)
        cls = None if args.json else local_class(type_, "msg")
        seen = 0

        async def work() -> None:
            nonlocal seen
            async with s.ros.subscribe(args.topic, type_, throttle_rate=args.throttle_ms,
                                       queue_length=args.queue_length) as sub:
                sub.uint8_as_sent = True  # printed in the wire form (--json keeps base64)
                async for msg in sub:
                    shown = for_display(msg, cls)
                    if args.field:
                        shown = _field(shown, args.field, type_)
                    out.record(shown, args.json, args.no_arr)
                    seen += 1
                    if args.count is not None and seen >= args.count:
                        return
            raise lost(s, f"echo {args.topic}")

        await until(duration, work())
        return EXIT_OK
    return await with_session(args, body)


def _field(msg: Any, path: str, type_: str) -> Any:
    """The field ``path`` (``a.b``) of a displayed message; a CliError names a wrong step."""
    value = msg
    for i, step in enumerate(path.split(".")):
        if not isinstance(value, dict) or step not in value:
            where = ".".join(path.split(".")[:i]) or type_
            fields = ", ".join(value) if isinstance(value, dict) else "none: not a message"
            raise CliError(EXIT_USAGE, f"--field {path}: {where} has no field {step!r} "
                                       f"(fields: {fields})")
        value = value[step]
    return value


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

    async def body(s: CliSession) -> int:
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
                out.line(json.dumps(nan_to_none(report)))
            else:
                out.line(f"average rate: {report['rate']:.3f}")
                out.line(f"\tmin: {report['min']:.3f}s max: {report['max']:.3f}s "
                         f"std dev: {report['std_dev']:.5f}s window: {report['window']}")

        async def work() -> None:
            async with s.ros.subscribe(args.topic, type_, queue_length=args.queue_length,
                                       buffer_size=10_000) as sub:
                sub.uint8_as_sent = True  # only counted: no decoding of byte arrays
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
                        raise lost(s, f"hz {args.topic}") from None
                    stats.add(loop.time())
                    if args.count is not None and stats.total >= args.count:
                        return

        try:
            await until(duration, work())
        finally:
            if stats.total != last_total and stats.report() is not None:
                show()
        return EXIT_OK
    return await with_session(args, body)


async def cmd_topic_pub(args: argparse.Namespace, out: Out) -> int:
    """``topic pub TOPIC TYPE [VALUES]``: publish once, N times, or at a rate until Ctrl+C."""
    type_parts(args.type, "msg")
    cls = local_class(args.type, "msg")
    values = check_values(cli_values(args.values, "VALUES"), cls, "VALUES")
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

    async def body(s: CliSession) -> int:
        pub = s.ros.advertise(args.topic, args.type, latch=args.latch)
        try:  # our bridge confirms or refuses at once; a stock one is asked below
            await pub
        except RemoteError as exc:
            pub.error = exc
        # A rosapi round trip: the bridge has handled our advertise when it answers.
        subscribers = (await s.rosapi("subscribers", {"topic": args.topic})).get("subscribers", [])
        if pub.error is not None:
            raise CliError(EXIT_REMOTE, f"the bridge refused to advertise {args.topic}: "
                                        f"{pub.error}")
        if len(subscribers) < wait_subs:
            if not args.quiet:
                print(f"Waiting for at least {wait_subs} matching subscription(s) on "
                      f"{args.topic}... (none yet; Ctrl+C stops, "
                      "--wait-matching-subscriptions 0 publishes without waiting)",
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
    return await with_session(args, body)


def add_parsers(groups: Any, kit: Kit) -> None:
    """Add ``topic`` and its commands."""
    tsub = kit.group(groups, "topic", "topics: list, type, find, info, echo, pub, hz, bw, delay",
                     "list,type,find,info,echo,pub,hz,bw,delay")
    kit.listing(tsub, cmd_topic_list, "list the topics in the ROS graph", "topic", hidden=True)
    p = kit.leaf(tsub, "type", cmd_topic_type, "print a topic's type", kit.wait)
    p.add_argument("topic")
    kit.finding(tsub, cmd_topic_find, "topic", "std_msgs/msg/String")
    p = kit.leaf(tsub, "info", cmd_topic_info, "a topic's type, publishers and subscribers",
             kit.fmt, kit.wait)
    p.add_argument("topic")
    p.add_argument("-v", "--verbose", action="store_true", help="list the nodes")
    p = kit.leaf(tsub, "echo", cmd_topic_echo,
             "print messages (YAML documents separated by ---, or --json lines)", kit.fmt, kit.wait)
    p.add_argument("topic")
    p.add_argument("type", nargs="?", help="message type (default: looked up in the graph)")
    p.add_argument("--count", "-n", type=int, help="stop after this many messages")
    p.add_argument("--once", action="store_true", help="print one message and exit (--count 1)")
    p.add_argument("--field", help="print only this field (a.b for nested ones), as ros2 does")
    p.add_argument("--duration", type=float, help="stop after this many seconds")
    p.add_argument("--no-arr", action="store_true", help="print sequences as their length")
    p.add_argument("--throttle-ms", type=int, default=0,
                   help="minimum ms between messages (default 0: every one)")
    p.add_argument("--queue-length", type=int, default=0,
                   help="the bridge's queue for us (default 0: the bridge's --send-queue)")
    p = kit.leaf(tsub, "pub", cmd_topic_pub, "publish a message", )
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
    p = kit.leaf(tsub, "hz", cmd_topic_hz, "print the publishing rate every second", kit.fmt,
                 kit.wait)
    p.add_argument("topic")
    p.add_argument("type", nargs="?", help="message type (default: looked up in the graph)")
    p.add_argument("--window", "-w", type=int, default=10000,
                   help="messages the statistics cover (default 10000)")
    p.add_argument("--count", "-n", type=int, help="stop after this many messages")
    p.add_argument("--duration", type=float, help="stop after this many seconds")
    p.add_argument("--queue-length", type=int, default=0,
                   help="the bridge's queue for us (default 0: the bridge's --send-queue)")
    topic_stats.add_parsers(tsub, kit)
