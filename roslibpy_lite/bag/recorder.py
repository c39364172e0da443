"""Recording topics through the bridge into MCAP (see the package docstring)."""

from __future__ import annotations

import asyncio
import contextlib
import fnmatch
import logging
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import IO, TYPE_CHECKING, Self

from ..api import ConnectionState
from ..exceptions import RosLibError, UsageError
from ..messages import RawMessage
from ._mcap import ROS2_PROFILE, SCHEMA_ENCODING, format_size, need_mcap, qos_yaml

if TYPE_CHECKING:
    from mcap.writer import Writer

    from ..api import Ros
    from ..handles import Subscription

__all__ = ["RecordStats", "Recorder", "empty_recording"]

log = logging.getLogger("roslibpy_lite.bag")

_PATTERN_CHARS = frozenset("*?[")


@dataclass
class RecordStats:
    """What a recording wrote. ``bytes``: the messages' own bytes (CDR); ``file_bytes``:
    the files' size on disk once stopped (compressed, with index and summary);
    ``dropped``: messages lost on this side (a full receive buffer or bytes that could
    not be taken); ``gaps``: seconds without a connection, one entry per reconnect;
    ``error``: why the recording ended early (None: it did not)."""

    messages: int = 0
    bytes: int = 0
    file_bytes: int = 0
    per_topic: dict[str, int] = field(default_factory=dict)
    dropped: int = 0
    gaps: list[float] = field(default_factory=list)
    files: list[Path] = field(default_factory=list)
    started: float = 0.0
    ended: float = 0.0
    error: str | None = None

    @property
    def duration(self) -> float:
        """Seconds from start to stop (so far, while recording)."""
        return (self.ended or time.monotonic()) - self.started if self.started else 0.0

    def line(self) -> str:
        """One line for a live display: topics, messages, their size (and the files' once
        stopped), rates, drops."""
        seconds = max(self.duration, 1e-9)
        gaps = f", {len(self.gaps)} gap(s) {sum(self.gaps):.1f} s" if self.gaps else ""
        on_disk = f" ({format_size(self.file_bytes)} on disk)" if self.file_bytes else ""
        return (f"{len(self.per_topic)} topics, {self.messages} msgs, "
                f"{format_size(self.bytes)} of messages{on_disk}, "
                f"{self.messages / seconds:.0f} msg/s, {format_size(self.bytes / seconds)}/s, "
                f"{self.dropped} dropped{gaps}")


class Recorder:
    """Records topics to an MCAP file until stopped (``async with`` or :meth:`start` /
    :meth:`stop`).

    ``topics``: names or fnmatch patterns (``/camera/*``), or a mapping name -> type
    (needed on MockRos, which has no rosapi; saves a lookup on a bridge).
    ``all_topics``: every topic. Topics that appear later are picked up (the bridge is
    asked every ``discover_every`` seconds). ``max_messages``: stop after that many
    (:meth:`wait` returns). ``split_size`` (bytes) / ``split_duration`` (seconds): go on
    in ``<stem>_1.mcap``, ``<stem>_2.mcap``... ``chunk_size``: bytes per MCAP chunk; a
    recorder that is killed leaves a file readable up to its last whole chunk.
    A connection that drops and comes back goes on in the same file (the gap is in
    :attr:`stats` and in the file's ``roslibpy_lite`` metadata). A write that fails
    (disk full, file gone) ends the recording with :attr:`RecordStats.error` set and the
    file closed as far as it can be. :meth:`stop` leaves a finished file whenever it is
    called: also after a :meth:`start` that failed or was cancelled half-way (an empty
    file if it had not opened one yet).
    """

    def __init__(
        self,
        ros: Ros,
        path: str | Path,
        *,
        topics: Sequence[str] | Mapping[str, str] = (),
        all_topics: bool = False,
        max_messages: int | None = None,
        split_size: int | None = None,
        split_duration: float | None = None,
        chunk_size: int = 256 * 1024,
        discover_every: float = 1.0,
        buffer_size: int = 10_000,
    ) -> None:
        need_mcap()
        if not topics and not all_topics:
            raise UsageError("record: name topics (or patterns), or pass all_topics=True")
        self.ros = ros
        self.path = Path(path)
        typed = dict(topics) if isinstance(topics, Mapping) else {}
        names = list(typed) if typed else list(topics)
        self._typed = typed
        self._exact = {n for n in names if not _PATTERN_CHARS & set(n)}
        self._patterns = [n for n in names if _PATTERN_CHARS & set(n)]
        self.all_topics = all_topics
        self.max_messages = max_messages
        self.split_size = split_size
        self.split_duration = split_duration
        self.chunk_size = chunk_size
        self.discover_every = discover_every
        self.buffer_size = buffer_size
        self.stats = RecordStats()
        self._subs: dict[str, Subscription[RawMessage]] = {}
        self._types: dict[str, tuple[str, str]] = {}  # topic -> (type, definition text)
        self._qos: dict[str, str] = {}  # topic -> rosbag2's offered_qos_profiles
        self._channels: dict[str, int] = {}
        self._schemas: dict[str, int] = {}
        self._file: IO[bytes] | None = None
        self._writer: Writer | None = None
        self._file_started = 0.0
        self._file_bytes = 0
        self._sequence = 0
        self._done = asyncio.Event()
        self._discovery: asyncio.Task[None] | None = None
        self._unwatch: Callable[[], None] | None = None
        self._down_since: float | None = None

    # -- life ------------------------------------------------------------------------------

    async def start(self) -> None:
        """Open the file, subscribe to what matches now, and keep discovering."""
        self.stats.started = time.monotonic()
        self._open(self.path)
        self._unwatch = self.ros.on_state_change(self._state)
        for topic, type_name in self._typed.items():
            await self._add(topic, type_name, None)
        if self._patterns or self.all_topics or self._exact - set(self._typed):
            await self._discover()
            self._discovery = asyncio.get_running_loop().create_task(
                self._discover_forever(), name="roslibpy_lite recorder discovery")

    async def wait(self, timeout: float | None = None) -> None:
        """Until ``max_messages`` are written or the recording fails (or ``timeout``)."""
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(timeout):  # keeps a cancel (3.11's wait_for may not)
                await self._done.wait()

    async def stop(self) -> RecordStats:
        """Finish the file properly (summary, index, footer), then unsubscribe.

        The file is finished before anything waits, so a stop that is itself cut short
        still leaves it whole; a recorder stopped before it opened its file (a
        :meth:`start` cancelled at once) writes an empty one.
        """
        if not self.stats.files and self.stats.error is None:
            self.stats.started = self.stats.started or time.monotonic()
            with contextlib.suppress(UsageError):  # cannot write it: stats.error says why
                self._open(self.path)
        if self._discovery is not None:
            self._discovery.cancel()
        if self._unwatch is not None:
            self._unwatch()
            self._unwatch = None
        self._close()
        self.stats.ended = time.monotonic()
        self.stats.file_bytes = sum(f.stat().st_size for f in self.stats.files if f.exists())
        if self._discovery is not None:
            with contextlib.suppress(asyncio.CancelledError):
                await self._discovery
            self._discovery = None
        for sub in self._subs.values():
            self.stats.dropped += sub.dropped + sub.decode_errors
            with contextlib.suppress(RosLibError):
                await sub.close()
        self._subs.clear()
        return self.stats

    async def __aenter__(self) -> Self:
        await self.start()
        return self

    async def __aexit__(
        self, et: type[BaseException] | None, e: BaseException | None, tb: TracebackType | None
    ) -> None:
        await self.stop()

    # -- topics ----------------------------------------------------------------------------

    def _wanted(self, topic: str) -> bool:
        return (self.all_topics or topic in self._exact
                or any(fnmatch.fnmatchcase(topic, p) for p in self._patterns))

    async def _discover(self) -> None:
        answer = await self.ros.call_service(
            "/rosapi/topics_and_raw_types", "rosapi_msgs/srv/TopicsAndRawTypes")
        for topic, type_name, text in zip(answer.get("topics", []), answer.get("types", []),
                                          answer.get("typedefs_full_text", []), strict=False):
            if topic not in self._subs and type_name and self._wanted(topic):
                await self._add(topic, type_name, text or None)

    async def _discover_forever(self) -> None:
        while True:
            await asyncio.sleep(self.discover_every)
            try:
                await self._discover()
            except RosLibError as exc:  # reconnecting: the next round asks again
                log.debug("recorder discovery: %s", exc)

    async def _add(self, topic: str, type_name: str, text: str | None) -> None:
        if text is None:
            text = await self._definition(type_name)
        self._types[topic] = (type_name, text)
        self._qos[topic] = await self._offered_qos(topic)
        self._register(topic)
        sub = self.ros.subscribe(topic, type_name, raw=True, buffer_size=self.buffer_size)
        sub.on_message(self._on_message)
        self._subs[topic] = sub
        self.stats.per_topic.setdefault(topic, 0)
        await sub

    async def _definition(self, type_name: str) -> str:
        from msgs.dynamic import full_text
        from msgs.runtime import UnknownTypeError

        try:
            return full_text(type_name)
        except UnknownTypeError:
            answer = await self.ros.call_service(
                "/rosapi/interface_definition", "rosapi_msgs/srv/InterfaceDefinition",
                {"type": type_name})
            text: str = answer["definition"]
            return text

    async def _offered_qos(self, topic: str) -> str:
        """The publishers' QoS as rosbag2 records it ("" where the bridge cannot say: a
        stock rosbridge, MockRos), so that players re-latch transient-local topics."""
        try:
            answer = await self.ros.call_service(
                "/rosapi/publishers_qos", "rosapi_msgs/srv/PublishersQos", {"topic": topic})
        except RosLibError as exc:
            log.debug("no QoS for %s: %s", topic, exc)
            return ""
        profiles = answer.get("qos")
        return qos_yaml(profiles) if isinstance(profiles, list) and profiles else ""

    # -- the file --------------------------------------------------------------------------

    def _open(self, path: Path) -> None:
        try:
            self._file, self._writer = _start_file(path, self.chunk_size)
        except OSError as exc:
            self._fail(f"cannot write {path}: {exc.strerror or exc}")
            raise UsageError(self.stats.error or "") from None
        self.stats.files.append(path)
        self._file_started = time.monotonic()
        self._file_bytes = 0
        self._schemas.clear()
        self._channels.clear()
        for topic in self._types:
            self._register(topic)

    def _register(self, topic: str) -> None:
        writer = self._writer
        if writer is None:
            return
        type_name, text = self._types[topic]
        schema = self._schemas.get(type_name)
        if schema is None:
            schema = self._schemas[type_name] = writer.register_schema(
                type_name, SCHEMA_ENCODING, text.encode())
        qos = self._qos.get(topic, "")
        self._channels[topic] = writer.register_channel(
            topic, "cdr", schema, metadata={"offered_qos_profiles": qos} if qos else {})

    def _on_message(self, raw: RawMessage) -> None:
        writer = self._writer
        if writer is None:
            return
        channel = self._channels.get(raw.topic)
        if channel is None:
            return
        self._sequence += 1
        try:
            writer.add_message(channel, log_time=time.time_ns(), data=raw.data,
                               publish_time=raw.stamp_ns, sequence=self._sequence)
        except OSError as exc:
            self._fail(f"cannot write {self.stats.files[-1]}: {exc.strerror or exc}")
            return
        stats = self.stats
        stats.messages += 1
        stats.bytes += len(raw.data)
        stats.per_topic[raw.topic] = stats.per_topic.get(raw.topic, 0) + 1
        self._file_bytes += len(raw.data)
        if self.max_messages is not None and stats.messages >= self.max_messages:
            self._done.set()
            self._close()
            return
        if ((self.split_size is not None and self._file_bytes >= self.split_size)
                or (self.split_duration is not None
                    and time.monotonic() - self._file_started >= self.split_duration)):
            self._close()
            index = len(self.stats.files)
            self._open(self.path.with_name(f"{self.path.stem}_{index}{self.path.suffix}"))

    def _close(self) -> bool:
        """Finish the current file (metadata, summary, footer); False if that failed."""
        writer, file = self._writer, self._file
        self._writer = self._file = None
        ok = True
        if writer is not None:
            try:
                if self.stats.gaps:
                    writer.add_metadata("roslibpy_lite", {
                        "gaps_s": ",".join(f"{g:.3f}" for g in self.stats.gaps)})
                writer.finish()  # type: ignore[no-untyped-call]
            except OSError as exc:
                ok = False
                self._fail(f"cannot finish {self.stats.files[-1]}: {exc.strerror or exc}")
        if file is not None:
            try:
                file.close()
            except OSError as exc:
                ok = False
                self._fail(f"cannot close {self.stats.files[-1]}: {exc.strerror or exc}")
        return ok

    def _fail(self, why: str) -> None:
        if self.stats.error is None:
            self.stats.error = why
            log.error("recording stopped: %s", why)
        self._writer = None
        self._done.set()

    def _state(self, state: ConnectionState) -> None:
        now = time.monotonic()
        if state is ConnectionState.RECONNECTING and self._down_since is None:
            self._down_since = now
        elif state is ConnectionState.CONNECTED and self._down_since is not None:
            gap = now - self._down_since
            self._down_since = None
            self.stats.gaps.append(gap)
            log.warning("recording: the connection was down for %.1f s; going on in %s",
                        gap, self.stats.files[-1] if self.stats.files else self.path)


def _start_file(path: Path, chunk_size: int) -> tuple[IO[bytes], Writer]:
    """``path`` opened for writing, with an MCAP writer that has written its header."""
    from mcap import writer as mcap

    file = path.open("wb")
    try:
        writer = mcap.Writer(file, chunk_size=chunk_size, compression=mcap.CompressionType.ZSTD)
        writer.start(profile=ROS2_PROFILE, library="roslibpy-lite")
    except BaseException:
        file.close()
        raise
    return file, writer


def empty_recording(path: str | Path) -> RecordStats:
    """Write a finished MCAP file with no messages at ``path``: what a recording stopped
    before it had a connection to subscribe on leaves (readable as any other). Raises
    :class:`OSError` if the file cannot be written."""
    need_mcap()
    path = Path(path)
    stats = RecordStats(files=[path], started=time.monotonic())
    file, writer = _start_file(path, 1024)
    with file:
        writer.finish()  # type: ignore[no-untyped-call]
    stats.ended = time.monotonic()
    stats.file_bytes = path.stat().st_size
    return stats
