"""MCAP decompression bombs (issue 53, finding 10): a few-KB file whose chunk unpacks to
256 MiB is refused before it is unpacked, by the table reader and the message reader
alike, and a chunk whose head lies about its size cannot make either unpack more than
it said. Peak memory is measured in a fresh process (``ru_maxrss`` after the imports)."""

from __future__ import annotations

import json
import re
import struct
import subprocess
import sys
from pathlib import Path

import lz4.frame  # type: ignore[import-untyped]
import pytest
import zstandard
from mcap.data_stream import RecordBuilder
from mcap.records import (
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    MessageIndex,
    Schema,
    Statistics,
)

from roslibpy_lite.bag import _bounds
from roslibpy_lite.bag._mcap import ROS2_PROFILE, SCHEMA_ENCODING

MIB = 1 << 20
BOMB = 256 * MIB
T0 = 1_700_000_000 * 10**9
_MAGIC = b"\x89MCAP0\r\n"


def _packed(text_size: int, compression: str, state_size: bool) -> tuple[bytes, int]:
    """One chunk's records (a std_msgs/String of ``text_size`` 'a's), compressed a MiB
    at a time so that this process never holds them: (compressed, uncompressed size)."""
    payload = 4 + 4 + text_size + 1  # CDR head, string length, the text, its NUL
    head = struct.pack("<BQHIQQ", 0x05, 2 + 4 + 8 + 8 + payload, 1, 0, T0, T0)
    head += b"\x00\x01\x00\x00" + struct.pack("<I", text_size + 1)
    size = len(head) + text_size + 1
    pieces = [head, *([b"a" * MIB] * (text_size // MIB)), b"a" * (text_size % MIB) + b"\0"]
    if compression == "zstd":
        z = zstandard.ZstdCompressor(write_content_size=state_size).compressobj(
            size=size if state_size else -1)
        return b"".join([*(z.compress(p) for p in pieces), z.flush()]), size
    lz = lz4.frame.LZ4FrameCompressor()
    return b"".join([lz.begin(size if state_size else 0),
                     *(lz.compress(p) for p in pieces), lz.flush()]), size


def write_bomb(path: Path, text_size: int = BOMB, *, said: int | None = None,
               compression: str = "zstd", state_size: bool = True) -> int:
    """An indexed ROS 2 MCAP file of one String message in one chunk, the chunk's head
    saying ``said`` bytes (its true size by default); its file size."""
    data, size = _packed(text_size, compression, state_size)
    b = RecordBuilder()
    b.write(_MAGIC)
    Header(profile=ROS2_PROFILE, library="bomb").write(b)
    schema = Schema(id=1, name="std_msgs/msg/String", encoding=SCHEMA_ENCODING,
                    data=b"string data\n")
    channel = Channel(id=1, schema_id=1, topic="/text", message_encoding="cdr", metadata={})
    schema.write(b)
    channel.write(b)
    chunk_at = b.count
    Chunk(compression=compression, data=data, message_start_time=T0, message_end_time=T0,
          uncompressed_crc=0, uncompressed_size=size if said is None else said).write(b)
    index_at = b.count
    MessageIndex(channel_id=1, records=[(T0, 0)]).write(b)
    index_end = b.count
    DataEnd(data_section_crc=0).write(b)
    summary_at = b.count
    schema.write(b)
    channel.write(b)
    Statistics(message_count=1, schema_count=1, channel_count=1, attachment_count=0,
               metadata_count=0, chunk_count=1, message_start_time=T0,
               message_end_time=T0, channel_message_counts={1: 1}).write(b)
    ChunkIndex(message_start_time=T0, message_end_time=T0, chunk_start_offset=chunk_at,
               chunk_length=index_at - chunk_at, message_index_offsets={1: index_at},
               message_index_length=index_end - index_at, compression=compression,
               compressed_size=len(data),
               uncompressed_size=size if said is None else said).write(b)
    Footer(summary_start=summary_at, summary_offset_start=0, summary_crc=0).write(b)
    b.write(_MAGIC)
    path.write_bytes(b.end())  # type: ignore[no-untyped-call]
    return path.stat().st_size


_MEASURE = """
import json, resource, sys
import pandas, numpy, mcap.reader, zstandard, lz4.frame  # the imports are not the load
import roslibpy_lite.data, roslibpy_lite.bag
from roslibpy_lite.exceptions import UsageError

def peak():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024

before = peak()
out = {}
for name, call in (("table", lambda: roslibpy_lite.data.bag_to_dataframe(sys.argv[1], "/text")),
                   ("messages", lambda: [len(m.data) for m in roslibpy_lite.bag.read(sys.argv[1])])):
    try:
        got = call()
        out[name] = {"rows": len(got)}
    except UsageError as exc:
        out[name] = {"error": str(exc)}
out["rise_mib"] = (peak() - before) / (1 << 20)
print(json.dumps(out))
"""


def _measure(path: Path) -> dict[str, object]:
    """Both readers on ``path`` in a fresh process: each one's rows or error, and how far
    the process's peak memory rose over what the imports took."""
    done = subprocess.run([sys.executable, "-c", _MEASURE, str(path)], capture_output=True,
                          text=True, timeout=120, check=False,
                          cwd=Path(__file__).resolve().parents[2])
    assert done.returncode == 0, done.stderr[-2000:]
    result: dict[str, object] = json.loads(done.stdout)
    return result


def test_a_few_kb_that_unpack_to_256_mib_are_refused_before_unpacking(tmp_path: Path) -> None:
    """The red team's bomb (one chunk saying, truthfully, 256 MiB): both readers refuse it
    naming the chunk's offset, its sizes and the limit, and peak memory rises < 48 MiB."""
    path = tmp_path / "bomb.mcap"
    size = write_bomb(path)
    assert size < 20_000
    got = _measure(path)
    limit = _bounds.chunk_limit(size)
    for name in ("table", "messages"):
        error = got[name]["error"]  # type: ignore[index]
        assert str(path) in error and f"unpacks to {BOMB + 40} bytes from" in error, got
        assert "the chunk at byte " in error and f"limit of {limit} bytes" in error, got
    assert got["rise_mib"] < 48, got  # type: ignore[operator]


@pytest.mark.parametrize(("compression", "state_size", "why"), [
    # the table reader unpacks only up to its message's end: that record says too much
    ("zstd", False, "does not unpack to the 4096 bytes it says|past the chunk's 4096"),
    ("zstd", True, "its zstd frame says 268435496"),
    ("lz4", False, "unpacks to more than the 4096 bytes it says"),
    ("lz4", True, "its lz4 frame says 268435496"),
])
def test_a_chunk_head_that_says_less_than_it_holds_cannot_unpack_more(
        tmp_path: Path, compression: str, state_size: bool, why: str) -> None:
    """A chunk saying 4 KiB that holds 256 MiB (its frame stating that size, or none):
    refused by both readers, naming why, with peak memory rising < 48 MiB."""
    path = tmp_path / f"liar-{compression}.mcap"
    write_bomb(path, said=4096, compression=compression, state_size=state_size)
    got = _measure(path)
    for name in ("table", "messages"):
        error = got[name]["error"]  # type: ignore[index]
        assert re.search(f"the chunk at byte \\d+ .*({why})", error), got
    assert got["rise_mib"] < 48, got  # type: ignore[operator]


def test_what_unpacks_within_the_floor_is_read(tmp_path: Path) -> None:
    """A 16 MiB message in a few KB (a ratio far past 100, under the 64 MiB floor) still
    reads, by both readers: the bound refuses bombs, not blank camera frames."""
    path = tmp_path / "blank.mcap"
    write_bomb(path, 16 * MIB)
    got = _measure(path)
    assert got["table"] == {"rows": 1} and got["messages"] == {"rows": 1}, got
