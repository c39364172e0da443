"""rosbag2's own recordings: a directory (``metadata.yaml`` and its ``.db3`` SQLite or
``.mcap`` files, split files in order) or a bare ``.db3`` file, read with ``rosbags``
(``pip install 'roslibpy-lite[rosbag2]'``), which parses the metadata of every rosbag2
version and reads the SQLite storage.

What :func:`~roslibpy_lite.bag.read`, :func:`~roslibpy_lite.bag.info`,
:func:`~roslibpy_lite.bag.play` and :func:`~roslibpy_lite.data.bag_to_dataframe` do with
a path that is one of these lives here. The MCAP files of a directory (uncompressed as
files) are read by this package's own MCAP path, file by file, chunk heads bounded as for
any MCAP file; ``.db3`` files (and MCAP files rosbag2 compressed whole) through rosbags'
storage readers. A directory's files are merged in log-time order. A recording compressed
per message has each message unpacked with the same bound as an MCAP chunk; one compressed
as whole files has each file unpacked as a stream first, held to the same ratio, before
rosbags writes it out.
"""

from __future__ import annotations

import heapq
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from ..exceptions import UsageError
from . import _bounds
from ._mcap import MESSAGE_ENCODING, need_mcap, qos_yaml
from ._mcapread import read_mcap
from ._records import BagInfo, BagMessage, TopicChunks, TopicInfo

MISSING = ("reading a rosbag2 recording needs the rosbag2 extra: "
           "pip install 'roslibpy-lite[rosbag2]'")
"""What is said when ``rosbags`` is missing."""

_BATCH_MESSAGES = 4096
_BATCH_BYTES = 4 << 20  # a batch of a .db3 topic for the table reader: like an MCAP chunk


def is_rosbag2(path: Path) -> bool:
    """Whether ``path`` is to be read as rosbag2's (a directory, or a ``.db3`` file)."""
    return path.is_dir() or path.suffix == ".db3"


def need_reader(path: str | Path) -> None:
    """Raise a UsageError naming the extra to install when what reads ``path`` is missing."""
    if not is_rosbag2(Path(path)):
        need_mcap()
        return
    try:
        import rosbags.rosbag2  # noqa: F401
    except ImportError:
        raise UsageError(MISSING) from None


@contextmanager
def _opened(path: Path) -> Iterator[Any]:
    """rosbags' reader of ``path``, open; its errors said as UsageErrors naming the path."""
    need_reader(path)
    from rosbags.rosbag2 import Reader, ReaderError

    if not path.exists():
        raise FileNotFoundError(f"no such file: {path}")
    if path.is_dir() and not (path / "metadata.yaml").exists():
        raise UsageError(f"{path}: a directory without a metadata.yaml: not a rosbag2 "
                         "recording (an MCAP file is read by its own name)")
    try:  # rosbags unpacks whole compressed files into a temporary directory: bound them
        for packed in sorted(path.glob("*.zstd")) if path.is_dir() else ():
            _bounds.check_whole_file(packed)
    except _bounds.ChunkBoundError as exc:
        raise UsageError(str(exc)) from None
    try:
        reader = Reader(path)
        reader.open()
    except (ReaderError, OSError, KeyError, ValueError) as exc:
        raise UsageError(f"{path}: not a readable rosbag2 recording: {exc}") from None
    try:
        yield reader
    finally:
        reader.close()


def _storages(reader: Any) -> list[Any]:
    """The reader's storage files in the metadata's order (one for a bare file)."""
    return list(getattr(reader.storage, "storages", [reader.storage]))


def _mcap_files(reader: Any) -> list[Path] | None:
    """The MCAP files of a directory this package reads itself (None: rosbags reads them)."""
    if reader.compression_mode is not None:
        return None
    files = [Path(storage.path) for storage in _storages(reader)]
    return files if files and all(f.suffix == ".mcap" for f in files) else None


def _definitions(path: Path, reader: Any, topics: set[str] | None) -> dict[str, str]:
    """The ``ros2msg`` text of each type of ``topics`` (None: all): the recording's, else
    msgs' own (a .db3 from before rosbag2 stored definitions); a type neither has is
    refused by name."""
    from rosbags.interfaces import MessageDefinitionFormat

    found: dict[str, str] = {}
    for storage in _storages(reader):
        for conn in storage.connections:
            if conn.msgdef.format == MessageDefinitionFormat.MSG and conn.msgdef.data:
                found.setdefault(conn.msgtype, conn.msgdef.data)
    for conn in reader.connections:
        if conn.msgtype not in found and (topics is None or conn.topic in topics):
            from msgs.dynamic import full_text

            try:
                found[conn.msgtype] = full_text(conn.msgtype)
            except Exception:
                raise UsageError(f"{path}: {conn.topic}'s type {conn.msgtype} has no ros2msg "
                                 "definition in the recording, and msgs does not know it"
                                 ) from None
    return found


def _unpack(path: Path, reader: Any, size: int) -> Any:
    """What turns a stored message into its CDR bytes (per-message compression unpacked,
    bounded as an MCAP chunk is by the recording's size)."""
    if reader.compression_mode != "message":
        return lambda data: data

    def unpack(data: bytes) -> bytes:
        try:
            return _bounds.decompress_message(data, size)
        except _bounds.ChunkBoundError as exc:
            raise UsageError(f"{path}: {exc}") from None
    return unpack


def _size(path: Path) -> int:
    """The recording's size: its directory's files (as rosbag2 counts it), or the file's."""
    if path.is_dir():
        return sum(f.stat().st_size for f in path.iterdir() if f.is_file())
    return path.stat().st_size


def _stored(reader: Any, topics: set[str] | None, start_ns: int | None,
            end_ns: int | None) -> Iterator[tuple[Any, int, bytes]]:
    """(storage connection, log time, stored bytes) of every storage, in log-time order
    (equal times: the earlier file first)."""
    streams = []
    for storage in _storages(reader):
        conns = [c for c in storage.connections if topics is None or c.topic in topics]
        if conns:
            streams.append(storage.messages(conns, start_ns, end_ns))
    return heapq.merge(*streams, key=lambda rec: rec[1])


def read(path: Path, topics: Iterable[str] | None, start_ns: int | None,
         end_ns: int | None) -> Iterator[BagMessage]:
    """:func:`roslibpy_lite.bag.read` of a rosbag2 recording (publish time = log time,
    which is all a .db3 keeps)."""
    wanted = None if topics is None else set(topics)
    with _opened(path) as reader:
        files = _mcap_files(reader)
        if files is not None:
            yield from heapq.merge(*(read_mcap(f, wanted, start_ns, end_ns)
                                     for f in files), key=lambda m: m.log_time_ns)
            return
        texts = _definitions(path, reader, wanted)
        unpack = _unpack(path, reader, _size(path))
        for conn, stamp, data in _stored(reader, wanted, start_ns, end_ns):
            if conn.ext.serialization_format == MESSAGE_ENCODING:
                yield BagMessage(conn.topic, conn.msgtype, stamp, stamp, bytes(unpack(data)),
                                 texts[conn.msgtype])


def info(path: Path) -> BagInfo:
    """:func:`roslibpy_lite.bag.info` of a rosbag2 recording, from its metadata (a bare
    .db3: from its tables)."""
    from rosbags.rosbag2.metadata import dump_qos_v9

    with _opened(path) as reader:
        by_topic: dict[str, TopicInfo] = {}
        for conn in reader.connections:
            found = by_topic.get(conn.topic)
            if found is None:
                try:
                    qos = qos_yaml([dict(p) for p in dump_qos_v9(conn.ext.offered_qos_profiles)])
                except UsageError:
                    qos = ""
                by_topic[conn.topic] = TopicInfo(conn.topic, conn.msgtype, conn.msgcount, qos)
            else:
                found.messages += conn.msgcount
        count = reader.message_count
        storages = _storages(reader)
        kind = "mcap" if all(Path(s.path).suffix == ".mcap" for s in storages) else "sqlite3"
        files = f", {len(storages)} files" if len(storages) > 1 else ""
        return BagInfo(path, _size(path), count, reader.start_time if count else 0,
                       reader.end_time - 1 if count else 0,  # rosbags' end is past the last
                       [by_topic[t] for t in sorted(by_topic)], True,
                       f"rosbag2 ({kind}{files})")


def topic_chunks(path: Path, topic: str) -> TopicChunks | None:
    """:func:`._chunks.topic_chunks` of a rosbag2 recording: its MCAP files' chunks one
    file after another, or its .db3 files' rows in batches (None: the general path)."""
    from ._chunks import topic_chunks as mcap_chunks

    with _opened(path) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        if not conns or len({c.msgtype for c in conns}) != 1:
            return None
        files = _mcap_files(reader)
        if files is not None:
            holding = [f for f, s in zip(files, _storages(reader), strict=True)
                       if any(c.topic == topic for c in s.connections)]
            found = [mcap_chunks(f, topic) for f in holding]
            kinds = {(f.type_name, f.definition) for f in found if f is not None}
            if None in found or len(kinds) != 1:
                return None
            (name, text), = kinds
            return TopicChunks(name, text, (batch for f in found if f is not None
                                            for batch in f.batches))
        text = _definitions(path, reader, {topic})[conns[0].msgtype]
    return TopicChunks(conns[0].msgtype, text, _batches(path, topic))


def _batches(path: Path, topic: str) -> Iterator[list[tuple[int, Any]]]:
    """The topic's (log time, CDR bytes) in batches of a few MiB, in log-time order."""
    with _opened(path) as reader:
        unpack = _unpack(path, reader, _size(path))
        batch: list[tuple[int, Any]] = []
        held = 0
        for _conn, stamp, data in _stored(reader, {topic}, None, None):
            data = unpack(data)
            batch.append((stamp, data))
            held += len(data)
            if len(batch) >= _BATCH_MESSAGES or held >= _BATCH_BYTES:
                yield batch
                batch, held = [], 0
        if batch:
            yield batch
