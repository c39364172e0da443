"""``roslibpy-lite bag record|info|play``: MCAP files through the bridge (roslibpy_lite.bag);
info and play read rosbag2 recordings too (a directory or a bare .db3 file)."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import signal
import sys
from collections.abc import Awaitable, Iterator
from typing import TYPE_CHECKING, Any

from ..exceptions import UsageError
from .common import (
    EXIT_ERROR,
    EXIT_NOT_FOUND,
    EXIT_OK,
    EXIT_USAGE,
    CliError,
    CliSession,
    Kit,
    Out,
    with_session,
)

if TYPE_CHECKING:
    from ..bag import Recorder


def _size(text: str) -> int:
    units = {"k": 1e3, "m": 1e6, "g": 1e9}
    text = text.strip().lower().removesuffix("b")
    scale = units.get(text[-1:], 1.0)
    try:
        return int(float(text[:-1] if text[-1:] in units else text) * scale)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a size: {text!r} (e.g. 500M, 2G)") from None


def _need_mcap(path: str | None = None) -> None:
    """Say that the extra is missing (and how to install it) before anything else: mcap's,
    or for a rosbag2 recording at ``path``, rosbag2's."""
    from ..bag._mcap import need_mcap
    from ..bag._rosbag2 import need_reader

    try:
        need_mcap() if path is None else need_reader(path)
    except UsageError as exc:
        raise CliError(EXIT_USAGE, str(exc)) from None


async def cmd_bag_record(args: argparse.Namespace, out: Out) -> int:
    """``bag record TOPIC... | --all -o FILE``: until Ctrl+C or SIGTERM, --duration, --max.

    SIGINT and SIGTERM end it properly from its first line on (``recording to FILE``),
    whatever it is doing: connecting, waiting for a topic, writing. The file is finished
    (an empty one if no connection came) and the ``recorded FILE: ...`` line says what it
    holds.
    """
    from ..bag import Recorder, empty_recording

    _need_mcap()

    if not args.topics and not args.all:
        raise CliError(EXIT_USAGE, "name topics (or patterns such as '/camera/*'), or pass --all")

    with _stop_signals() as stopped:
        _say(f"recording to {args.output}: connecting to {args.url}")
        made: list[Recorder] = []

        async def body(s: CliSession) -> int:
            try:
                rec = Recorder(s.ros, args.output, topics=args.topics, all_topics=args.all,
                               max_messages=args.max, split_size=args.split_size,
                               split_duration=args.split_duration)
            except UsageError as exc:
                raise CliError(EXIT_USAGE, str(exc)) from None
            made.append(rec)
            return await _record(rec, args, stopped, out)

        session = asyncio.ensure_future(with_session(args, body, reconnect=True))
        if await _until_stopped(asyncio.shield(session), stopped) or made:
            return await session  # over, or recording (which ends on the signal itself)
        session.cancel()  # stopped while connecting: nothing to subscribe on yet
        with contextlib.suppress(asyncio.CancelledError):
            await session
        try:
            stats = empty_recording(args.output)
        except OSError as exc:
            raise CliError(EXIT_ERROR, f"cannot write {args.output}: "
                           f"{exc.strerror or exc}") from None
        out.line(f"recorded {args.output}: {stats.line()}")
        return EXIT_OK


async def _record(rec: Recorder, args: argparse.Namespace, stopped: asyncio.Event, out: Out) -> int:
    """Run ``rec`` until ``stopped``, --duration or --max; finish its file and
    say what it holds, however it ends."""
    live = sys.stderr.isatty() and not args.quiet
    ticker: asyncio.Task[None] | None = None
    try:
        if await _until_stopped(rec.start(), stopped):
            waiting = [t for t in args.topics
                       if not set("*?[") & set(t) and t not in rec.stats.per_topic]
            _say(f"recording {len(rec.stats.per_topic)} topic(s)"
                 + (f"; waiting for {', '.join(waiting)}" if waiting else ""))

            async def show() -> None:
                while True:
                    await asyncio.sleep(1.0)
                    if live:
                        print("\r\x1b[K" + rec.stats.line(), end="", file=sys.stderr,
                              flush=True)

            ticker = asyncio.get_running_loop().create_task(show())
            await _until_stopped(rec.wait(args.duration), stopped)
    finally:
        if ticker is not None:
            ticker.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await ticker
        stats = await asyncio.shield(rec.stop())
        if live:
            print(file=sys.stderr)
        out.line(f"recorded {', '.join(str(f) for f in stats.files)}: {stats.line()}")
    if stats.error is not None:
        raise CliError(EXIT_ERROR, f"recording stopped: {stats.error} (the file is "
                       "readable up to there)")
    return EXIT_OK


async def _until_stopped(work: Awaitable[Any], stopped: asyncio.Event) -> bool:
    """Await ``work`` unless ``stopped`` is set first (then ``work`` is cancelled); True if
    ``work`` ended (its exception raised here)."""
    task = asyncio.ensure_future(work)
    signalled = asyncio.ensure_future(stopped.wait())
    try:
        await asyncio.wait({task, signalled}, return_when=asyncio.FIRST_COMPLETED)
    finally:
        signalled.cancel()
        if not task.done():
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
    if task.cancelled():
        return False
    task.result()
    return True


def _say(line: str) -> None:
    """A line about the recording's progress on stderr (stdout keeps the result)."""
    print(line, file=sys.stderr, flush=True)


@contextlib.contextmanager
def _stop_signals() -> Iterator[asyncio.Event]:
    """An event set by SIGINT or SIGTERM while inside, for a recording to end properly.

    Handled on the loop, not as KeyboardInterrupt: a ``kill`` (systemd, docker stop) finishes
    the file as Ctrl+C does, and so does a SIGINT to a recorder started in the background
    (which inherits SIGINT ignored, so Python would never raise KeyboardInterrupt). Where the
    loop cannot handle signals (Windows), Ctrl+C still ends it through KeyboardInterrupt.
    """
    loop = asyncio.get_running_loop()
    stopped = asyncio.Event()
    installed: list[signal.Signals] = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            loop.add_signal_handler(sig, stopped.set)
        except (NotImplementedError, RuntimeError, ValueError):
            continue
        installed.append(sig)
    try:
        yield stopped
    finally:
        for sig in installed:
            loop.remove_signal_handler(sig)


async def cmd_bag_info(args: argparse.Namespace, out: Out) -> int:
    """``bag info FILE``: topics, types, counts, duration, size (FILE: an MCAP file, a
    rosbag2 directory or a .db3 file)."""
    from ..bag import info
    from ..bag._mcap import format_size

    _need_mcap(args.file)

    try:
        about = info(args.file)
    except FileNotFoundError:
        raise CliError(EXIT_NOT_FOUND, f"no such file: {args.file}") from None
    except Exception as exc:
        raise CliError(EXIT_ERROR, f"{args.file} is not a readable recording: {exc}") from None
    unfinished = "" if about.complete else " (no summary: a recording that did not finish)"
    out.line(f"File:      {about.path}{unfinished}")
    out.line(f"Size:      {format_size(about.size)}")
    out.line(f"Duration:  {about.duration:.3f} s")
    out.line(f"Messages:  {about.messages}")
    if about.library:
        out.line(f"Writer:    {about.library}")
    for gaps in (about.metadata.get("roslibpy_lite", {}).get("gaps_s"),):
        if gaps:
            out.line(f"Gaps (s):  {gaps}")
    out.line("Topics:")
    width = max((len(t.topic) for t in about.topics), default=0)
    for t in about.topics:
        out.line(f"  {t.topic:<{width}}  {t.type_name}  {t.messages} msgs")
    return EXIT_OK


async def cmd_bag_play(args: argparse.Namespace, out: Out) -> int:
    """``bag play FILE``: publish through the bridge with the recorded timing."""
    from ..bag import play

    _need_mcap(args.file)

    async def body(s: CliSession) -> int:
        stats = await play(s.ros, args.file, rate=args.rate, loop=args.loop,
                           topics=args.topics or None, start=args.start,
                           duration=args.duration, latch=args.latch or ())
        out.line(f"played {stats.messages} messages on {stats.topics} topics "
                 f"(late by {stats.late_mean_ms:.1f} ms on average, "
                 f"{stats.late_max_ms:.1f} ms at most)")
        return EXIT_OK
    return await with_session(args, body)


def add_parsers(groups: Any, kit: Kit) -> None:
    """Add ``bag`` and its commands."""
    bsub = kit.group(groups, "bag", "MCAP files: record (through the bridge), info, play "
                     "(MCAP files and rosbag2 recordings)",
                     "record,info,play")
    p = kit.leaf(bsub, "record", cmd_bag_record, "record topics to an MCAP file (Ctrl+C ends "
                 "it properly)")
    p.add_argument("topics", nargs="*", metavar="TOPIC", help="names or patterns ('/cam/*')")
    p.add_argument("-a", "--all", action="store_true", help="every topic")
    p.add_argument("-o", "--output", required=True, help="the file, e.g. run.mcap")
    p.add_argument("--duration", type=float, default=None, metavar="SEC", help="stop after")
    p.add_argument("--max", type=int, default=None, metavar="N", help="stop after N messages")
    p.add_argument("--split-size", type=_size, default=None, metavar="SIZE",
                   help="go on in FILE_1.mcap... past this size (500M, 2G)")
    p.add_argument("--split-duration", type=float, default=None, metavar="SEC",
                   help="go on in a new file every SEC seconds")
    p.add_argument("-q", "--quiet", action="store_true", help="no live status line")
    p = kit.leaf(bsub, "info", cmd_bag_info, "topics, types, counts and times of a file")
    p.add_argument("file", help="an MCAP file, a rosbag2 directory or a .db3 file")
    p = kit.leaf(bsub, "play", cmd_bag_play, "publish a file through the bridge")
    p.add_argument("file", help="an MCAP file, a rosbag2 directory or a .db3 file")
    p.add_argument("--rate", type=float, default=1.0,
                   help="time scale (default 1; 2: twice as fast)")
    p.add_argument("--loop", action="store_true", help="start over at the end")
    p.add_argument("--topics", nargs="+", default=None, metavar="TOPIC", help="only these")
    p.add_argument("--start", type=float, default=0.0, metavar="SEC",
                   help="skip this many seconds from the start (default 0)")
    p.add_argument("--duration", type=float, default=None, metavar="SEC",
                   help="play this many seconds")
    p.add_argument("--latch", nargs="+", default=None, metavar="TOPIC",
                   help="advertise these latched too (rosbag2's QoS is read when present)")
