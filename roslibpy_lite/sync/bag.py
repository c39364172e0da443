"""Recording and playing MCAP files on the blocking client (``pip install roslibpy-lite[mcap]``).

The same as :mod:`roslibpy_lite.bag`, without ``await``; it works on
:class:`~roslibpy_lite.sync.Client` and :class:`~roslibpy_lite.sync.MockRos` alike::

    from roslibpy_lite import sync
    from roslibpy_lite.sync import bag

    with sync.connect("ws://robot:9090") as ros:
        with bag.Recorder(ros, "run.mcap", topics=["/imu", "/camera/*"]) as rec:
            time.sleep(60)
        print(rec.stats.line())
        bag.play(ros, "run.mcap", rate=2.0)

    for msg in bag.read("run.mcap"):
        print(msg.topic, msg.decode())

The recorder writes on the client's loop thread as messages arrive; your thread only
starts and stops it. :func:`read` and :func:`info` are plain functions already and are
the same objects as in :mod:`roslibpy_lite.bag`.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Self

from ..bag import BagInfo, BagMessage, PlayStats, RecordStats, TopicInfo, info, read
from ..bag import Recorder as _AioRecorder
from ..bag import play as _aio_play

if TYPE_CHECKING:
    from . import _Front

__all__ = ["BagInfo", "BagMessage", "PlayStats", "RecordStats", "Recorder", "TopicInfo",
           "info", "play", "read"]


class Recorder:
    """Records topics to an MCAP file until stopped (``with`` or :meth:`start` / :meth:`stop`).

    The options are those of :class:`roslibpy_lite.bag.Recorder`. Raises
    :class:`~roslibpy_lite.exceptions.UsageError` at :meth:`start` for a file that cannot
    be written, and ImportError naming the extra when ``mcap`` is missing.
    """

    def __init__(
        self,
        ros: _Front,
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
        self._loop = ros._loop
        self._recorder: _AioRecorder = self._loop.call(
            "Recorder", _AioRecorder, ros.aio, path, topics=topics, all_topics=all_topics,
            max_messages=max_messages, split_size=split_size, split_duration=split_duration,
            chunk_size=chunk_size, discover_every=discover_every, buffer_size=buffer_size)

    @property
    def stats(self) -> RecordStats:
        """What was written so far (updated on the loop thread as messages arrive)."""
        return self._recorder.stats

    def start(self) -> None:
        """Open the file, subscribe to what matches now, and keep discovering."""
        self._loop.run(self._recorder.start(), "record")

    def wait(self, timeout: float | None = None) -> None:
        """Until ``max_messages`` are written or the recording fails (or ``timeout``)."""
        self._loop.run(self._recorder.wait(timeout), "record wait")

    def stop(self) -> RecordStats:
        """Unsubscribe and finish the file properly; returns the final stats."""
        return self._loop.run(self._recorder.stop(), "record stop")

    def __enter__(self) -> Self:
        self.start()
        return self

    def __exit__(
        self, et: type[BaseException] | None, e: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()


def play(
    ros: _Front,
    path: str | Path,
    *,
    rate: float = 1.0,
    loop: bool = False,
    topics: Iterable[str] | None = None,
    start: float = 0.0,
    duration: float | None = None,
    latch: Iterable[str] = (),
) -> PlayStats:
    """Publish the messages of ``path`` with the recorded timing; blocks until done
    (Ctrl+C stops a ``loop=True`` play). See :func:`roslibpy_lite.bag.play`."""
    names: Sequence[str] | None = list(topics) if topics is not None else None
    return ros._loop.run(
        _aio_play(ros.aio, path, rate=rate, loop=loop, topics=names, start=start,
                  duration=duration, latch=list(latch)), f"play {path}")

