"""``roslibpy-lite topic bw|delay``: a topic's bandwidth and its messages' age, each second.

As ``ros2 topic bw`` and ``ros2 topic delay`` do and print them:

- ``bw`` counts each message's size as the robot serialized it (CDR with its 4-byte
  header: the bridge sends the bytes, ``raw`` subscription) over the last ``--window``
  messages: ``1.23 KB/s from 10 messages`` and ``\\tMessage size mean: ... min: ... max:``;
- ``delay`` is the time each message arrives here minus its ``header.stamp``, over the
  last ``--window`` messages: ``average delay: 0.012`` and ``\\tmin: ...s max: ...s std dev:
  ...s window: N``. Arrival is this machine's clock: the delay includes the hop from the
  robot, and any difference between the two clocks.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import time
from collections import deque
from collections.abc import Callable
from typing import Any

from .common import (
    EXIT_OK,
    EXIT_USAGE,
    CliError,
    CliSession,
    Kit,
    Out,
    local_class,
    lost,
    type_parts,
    until,
    with_session,
)

BW_WINDOW = 100
"""``topic bw``'s default window, in messages (ros2's)."""

DELAY_WINDOW = 10_000
"""``topic delay``'s default window, in messages (ros2's)."""


def _unit(bytes_per_s: float) -> tuple[float, str, str]:
    """ros2's unit for a bandwidth: (divisor, unit, number format)."""
    if bytes_per_s < 1000:
        return 1.0, "B", ".0f"
    if bytes_per_s < 1_000_000:
        return 1000.0, "KB", ".2f"
    return 1_000_000.0, "MB", ".2f"


class BandwidthStats:
    """Sizes and arrival times of the last ``window`` messages; ros2's bandwidth report."""

    def __init__(self, window: int) -> None:
        self.sizes: deque[int] = deque(maxlen=window)
        self.times: deque[float] = deque(maxlen=window)
        self.total = 0

    def add(self, t: float, size: int) -> None:
        """Record one message of ``size`` bytes arriving at ``t`` (seconds)."""
        self.times.append(t)
        self.sizes.append(size)
        self.total += 1

    def report(self, now: float) -> dict[str, Any] | None:
        """Bytes per second from the window's first arrival to ``now``, with the count and
        the mean/min/max size; None before two messages (or when ``now`` is not later)."""
        if len(self.times) < 2 or now <= self.times[0]:
            return None
        total = sum(self.sizes)
        n = len(self.sizes)
        return {"bytes_per_s": total / (now - self.times[0]), "messages": n,
                "mean": total / n, "min": min(self.sizes), "max": max(self.sizes)}


def bw_text(report: dict[str, Any]) -> str:
    """``ros2 topic bw``'s two lines for a report (every figure in the bandwidth's unit)."""
    div, unit, spec = _unit(report["bytes_per_s"])

    def show(x: float) -> str:
        return f"{x / div:{spec}} {unit}"

    return (f"{show(report['bytes_per_s'])}/s from {report['messages']} messages\n"
            f"\tMessage size mean: {show(report['mean'])} min: {show(report['min'])} "
            f"max: {show(report['max'])}")


class DelayStats:
    """Delays (arrival minus header stamp, ns) of the last ``window`` messages.

    As ros2 does, the first message only starts the count (its delay is not kept), and a
    clock that went back starts it again.
    """

    def __init__(self, window: int) -> None:
        self.delays: deque[int] = deque(maxlen=window)
        self.started: int | None = None
        self.received = 0
        self.reported = 0

    def add(self, now_ns: int, stamp_ns: int) -> None:
        """Record a message stamped ``stamp_ns`` arriving at ``now_ns``."""
        if self.started is None or self.started > now_ns:
            self.started = now_ns
            self.delays.clear()
        else:
            self.delays.append(now_ns - stamp_ns)
        self.received += 1

    def report(self) -> dict[str, Any] | None:
        """Mean/min/max/std dev (seconds) and window; None when nothing came since the last."""
        if not self.delays or self.received == self.reported:
            return None
        self.reported = self.received
        n = len(self.delays)
        mean = sum(self.delays) / n
        std = math.sqrt(sum((d - mean) ** 2 for d in self.delays) / n)
        return {"delay": mean * 1e-9, "min": min(self.delays) * 1e-9,
                "max": max(self.delays) * 1e-9, "std_dev": std * 1e-9, "window": n}


def delay_text(report: dict[str, Any]) -> str:
    """``ros2 topic delay``'s two lines for a report."""
    return (f"average delay: {report['delay']:.3f}\n"
            f"\tmin: {report['min']:.3f}s max: {report['max']:.3f}s "
            f"std dev: {report['std_dev']:.5f}s window: {report['window']}")


def stamp_ns(msg: Any, topic: str, type_: str) -> int:
    """The ``header.stamp`` of a message (dict) in nanoseconds; a CliError if it has none."""
    stamp = msg.get("header", {}).get("stamp") if isinstance(msg, dict) else None
    if not isinstance(stamp, dict):
        raise CliError(EXIT_USAGE, f"topic delay {topic}: its messages ({type_}) have no "
                                   "header.stamp to measure the delay from")
    return int(stamp.get("sec", 0)) * 1_000_000_000 + int(stamp.get("nanosec", 0))


def _checked(args: argparse.Namespace) -> float | None:
    if args.window < 1:
        raise CliError(EXIT_USAGE, f"--window must be >= 1, got {args.window}")
    if args.duration is not None and args.duration <= 0:
        raise CliError(EXIT_USAGE, f"--duration must be > 0, got {args.duration}")
    if args.count is not None and args.count < 1:
        raise CliError(EXIT_USAGE, f"--count must be >= 1, got {args.count}")
    if args.type:
        type_parts(args.type, "msg")
    duration: float | None = args.duration
    return duration


async def _every_second(s: CliSession, args: argparse.Namespace, sub: Any, what: str,
                        on_message: Callable[[Any], int], show: Callable[[], None]) -> None:
    """Read ``sub`` until ``--count`` messages (``on_message`` answers the count so far),
    calling ``show`` each second; a lost connection is a CliError."""
    loop = asyncio.get_running_loop()
    next_report = loop.time() + 1.0
    while True:
        try:
            async with asyncio.timeout_at(next_report):
                msg = await sub.__anext__()
        except TimeoutError:
            show()
            next_report += 1.0
            continue
        except StopAsyncIteration:
            raise lost(s, f"{what} {args.topic}") from None
        seen = on_message(msg)
        if args.count is not None and seen >= args.count:
            return


async def _type_of(s: CliSession, args: argparse.Namespace) -> str:
    return str(args.type) if args.type else await s.topic_type(args.topic, args.wait)


async def cmd_topic_bw(args: argparse.Namespace, out: Out) -> int:
    """``topic bw TOPIC``: the bandwidth the topic uses, each second."""
    duration = _checked(args)

    async def body(s: CliSession) -> int:
        type_ = await _type_of(s, args)
        stats = BandwidthStats(args.window)
        shown = -1

        def show() -> None:
            nonlocal shown
            report = stats.report(time.monotonic())
            if report is None:
                return
            shown = stats.total
            out.line(json.dumps(report) if args.json else bw_text(report))

        def on_message(msg: Any) -> int:
            stats.add(time.monotonic(), len(msg.data))
            return stats.total

        async with s.ros.subscribe(args.topic, type_, raw=True,
                                   queue_length=args.queue_length, buffer_size=10_000) as sub:
            if not args.json:
                out.line(f"Subscribed to [{args.topic}]")
            try:
                await until(duration, _every_second(s, args, sub, "bw", on_message, show))
            finally:
                if stats.total != shown:
                    show()
        return EXIT_OK
    return await with_session(args, body)


async def cmd_topic_delay(args: argparse.Namespace, out: Out) -> int:
    """``topic delay TOPIC``: how old the messages are when they arrive, each second."""
    duration = _checked(args)

    async def body(s: CliSession) -> int:
        type_ = await _type_of(s, args)
        cls = local_class(type_, "msg")
        if cls is not None and "header" not in cls._fields_and_types:
            raise CliError(EXIT_USAGE, f"topic delay {args.topic}: its messages ({type_}) "
                                       "have no header.stamp to measure the delay from")
        stats = DelayStats(args.window)

        def show() -> None:
            if not stats.delays:
                return
            report = stats.report()
            if report is None:
                if not args.json:
                    out.line("no new messages")
                return
            out.line(json.dumps(report) if args.json else delay_text(report))

        def on_message(msg: Any) -> int:
            stats.add(time.time_ns(), stamp_ns(msg, args.topic, type_))
            return stats.received

        async with s.ros.subscribe(args.topic, type_, queue_length=args.queue_length,
                                   buffer_size=10_000) as sub:
            sub.uint8_as_sent = True  # only the header is read: no decoding of byte arrays
            try:
                await until(duration, _every_second(s, args, sub, "delay", on_message, show))
            finally:
                if stats.received != stats.reported:
                    show()
        return EXIT_OK
    return await with_session(args, body)


def add_parsers(tsub: Any, kit: Kit) -> None:
    """Add ``topic bw`` and ``topic delay`` to ``topic``'s subparsers."""
    for name, fn, help_, window in (
        ("bw", cmd_topic_bw, "print the bandwidth a topic uses, each second", BW_WINDOW),
        ("delay", cmd_topic_delay, "print the delay of a topic's messages from their "
                                   "header stamps, each second", DELAY_WINDOW),
    ):
        p = kit.leaf(tsub, name, fn, help_, kit.fmt, kit.wait)
        p.add_argument("topic")
        p.add_argument("type", nargs="?", help="message type (default: looked up in the graph)")
        p.add_argument("--window", "-w", type=int, default=window,
                       help=f"messages the statistics cover (default {window})")
        p.add_argument("--count", "-n", type=int, help="stop after this many messages")
        p.add_argument("--duration", type=float, help="stop after this many seconds")
        p.add_argument("--queue-length", type=int, default=0,
                       help="the bridge's queue for us (default 0: the bridge's --send-queue)")
