"""rosbag2's own recordings (issue 52, item 3): directories with metadata.yaml and one or
more .db3 or MCAP files, and bare .db3 files, read back as the same messages, the same
info and the same tables as an MCAP file of the same messages; played through MockRos."""

from __future__ import annotations

import contextlib
import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path
from typing import Any, cast

import numpy as np
import pandas as pd
import pytest
import zstandard

import roslibpy_lite.data as data
from msgs import cdr
from msgs.sensor_msgs.msg import Imu, JointState
from msgs.std_msgs.msg import String
from roslibpy_lite import MockRos, UsageError
from roslibpy_lite.bag import _bounds, _rosbag2, info, play, read
from roslibpy_lite.data import bag_to_dataframe
from tests.bag.rosbag2_files import Entry, write_split, write_storage
from tests.bag.test_play import _KeepingPublishers
from tests.data.test_bag_columns import _write

T0 = 1_700_000_000 * 10**9
FIELDS = {"/imu": ["angular_velocity.z", "linear_acceleration"], "/joints": ["name", "position"],
          "/note": ["data"]}


def _entries() -> list[Entry]:
    """600 IMU (200 Hz), 150 JointState (strings of varying length) and 30 String (no
    header: indexed by log time) messages, interleaved, each with its own values."""
    rng = np.random.default_rng(7)
    out: list[Entry] = []
    for i in range(600):
        imu = Imu()
        imu.header.stamp.sec, imu.header.stamp.nanosec = divmod(T0 + i * 5_000_000, 10**9)
        imu.header.frame_id = "imu_link"
        imu.angular_velocity.z = float(rng.normal())
        imu.linear_acceleration.x, imu.linear_acceleration.z = float(rng.normal()), 9.81
        out.append(("/imu", Imu._type, T0 + i * 5_000_000 + 1_000, cdr.encode(imu)))
    for i in range(150):
        joints = JointState(name=[f"joint_{j}" * (1 + i % 3) for j in range(i % 4)],
                            position=[float(x) for x in rng.normal(size=i % 4)])
        joints.header.stamp.sec, joints.header.stamp.nanosec = divmod(T0 + i * 20_000_000,
                                                                      10**9)
        out.append(("/joints", JointState._type, T0 + i * 20_000_000 + 2_000,
                    cdr.encode(joints)))
    for i in range(30):
        out.append(("/note", String._type, T0 + i * 100_000_000 + 3_000,
                    cdr.encode(String(data=f"note {i}"))))
    return sorted(out, key=lambda e: e[2])


LAYOUTS = ["sqlite3", "sqlite3-split", "mcap", "mcap-split", "db3", "sqlite3-per-message",
           "sqlite3-per-file"]


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The same messages as an MCAP file (the reference) and in each rosbag2 layout."""
    root = tmp_path_factory.mktemp("rosbag2")
    entries = _entries()
    reference = root / "reference.mcap"
    _write(reference, [(topic, t, data, type_name) for topic, type_name, t, data in entries],
           chunk_size=16 * 1024)
    out = {"reference": reference,
           "sqlite3": write_storage(root / "run_sqlite3", entries, "sqlite3",
                                    latched=frozenset({"/note"})),
           "sqlite3-split": write_split(root / "run_split", entries, "sqlite3", 3),
           "mcap": write_storage(root / "run_mcap", entries, "mcap"),
           "mcap-split": write_split(root / "run_mcap_split", entries, "mcap", 3, version=8),
           "sqlite3-per-message": write_storage(root / "run_zstd", entries, "sqlite3",
                                                compression="message"),
           "sqlite3-per-file": write_storage(root / "run_file", entries, "sqlite3",
                                             compression="file")}
    out["db3"] = out["sqlite3"] / "run_sqlite3.db3"
    return out


@pytest.mark.parametrize("layout", LAYOUTS)
def test_a_rosbag2_recording_makes_the_same_tables_as_the_mcap_file(
        recordings: dict[str, Path], layout: str) -> None:
    """Every topic, with its field list and without, gives the very DataFrame the MCAP file
    of the same messages gives; and the table comes from the speed path (batches of CDR
    bytes into columns), not message by message."""
    for topic, fields in FIELDS.items():
        for chosen in (fields, None):
            want = bag_to_dataframe(recordings["reference"], topic, chosen)
            got = bag_to_dataframe(recordings[layout], topic, chosen)
            pd.testing.assert_frame_equal(got, want)
            fast = data._bag_columns(recordings[layout], topic, chosen)
            assert fast is not None, (topic, chosen)
            pd.testing.assert_frame_equal(fast, want)


@pytest.mark.parametrize("layout", LAYOUTS)
def test_a_rosbag2_recording_reads_as_the_same_messages_and_info(
        recordings: dict[str, Path], layout: str) -> None:
    """read() gives the same (topic, type, log time, CDR bytes) in the same order as the
    MCAP file, topics filtered and time-bounded alike; info() the same topics, types,
    counts and times (and the QoS a split directory's metadata.yaml gives); they decode."""
    def rows(path: Path, **kw: Any) -> list[tuple[str, str, int, bytes]]:
        return [(m.topic, m.type_name, m.log_time_ns, m.data) for m in read(path, **kw)]

    path = recordings[layout]
    assert rows(path) == rows(recordings["reference"])
    window: dict[str, Any] = {"topics": ["/joints", "/note"], "start_ns": T0 + 10**9,
                              "end_ns": T0 + 2 * 10**9}
    assert rows(path, **window) == rows(recordings["reference"], **window)
    assert [m.decode().to_json()["data"] for m in read(path, ["/note"])][:2] == ["note 0", "note 1"]
    got, want = info(path), info(recordings["reference"])
    assert [(t.topic, t.type_name, t.messages) for t in got.topics] == [
        (t.topic, t.type_name, t.messages) for t in want.topics]
    assert (got.messages, got.start_ns, got.end_ns) == (want.messages, want.start_ns,
                                                        want.end_ns)
    assert got.library.startswith("rosbag2") and got.size > 0
    if layout.endswith("split"):  # the QoS of metadata.yaml: names (version 9), numbers (8)
        assert all("durability: volatile" in t.qos for t in got.topics), got.topics


def test_bag_info_prints_a_split_directory(recordings: dict[str, Path]) -> None:
    """``roslibpy-lite bag info DIR`` on a directory of three .db3 files (rosbag2's
    metadata.yaml): its writer, count and each topic's type and count."""
    done = subprocess.run([sys.executable, "-m", "roslibpy_lite.cli", "bag", "info",
                           str(recordings["sqlite3-split"])], capture_output=True, text=True,
                          timeout=60, check=False)
    assert done.returncode == 0, done.stderr
    assert "Writer:    rosbag2 (sqlite3, 3 files)" in done.stdout
    assert "Messages:  780" in done.stdout
    assert "/joints  sensor_msgs/msg/JointState  150 msgs" in done.stdout


async def test_bag_play_publishes_a_db3_recording_with_its_latched_topic(
        recordings: dict[str, Path]) -> None:
    """play() of a rosbag2 directory publishes its messages in recorded order, and the
    topic its QoS says is transient local is advertised latched: a subscriber that comes
    after the play gets its last message, one of an unlatched topic gets nothing."""
    seen: list[list[str]] = []
    async with MockRos() as ros:
        sub = await ros.subscribe("/joints", "sensor_msgs/msg/JointState")
        sub.on_message(lambda m: seen.append(m["name"]))
        held = _KeepingPublishers(ros)
        stats = await play(cast(Any, held), recordings["sqlite3"], topics=["/note", "/joints"],
                           rate=20.0)
        late_note = await ros.subscribe("/note", "std_msgs/msg/String")
        late_joints = await ros.subscribe("/joints", "sensor_msgs/msg/JointState")
        assert (await late_note.get(timeout=5))["data"] == "note 29"
        await ros.drain()  # delivery in MockRos is done once this returns
        assert late_joints.received == 0
        for pub in held.kept:
            await pub.close()
    assert seen == [JointState.from_json(cdr.decode(data, JointState)).name
                    for topic, _, _, data in _entries() if topic == "/joints"]
    assert stats.messages == 180 and stats.topics == 2


def test_what_is_not_a_rosbag2_recording_or_lacks_the_extra_is_said(
        tmp_path: Path, recordings: dict[str, Path], monkeypatch: pytest.MonkeyPatch) -> None:
    """A directory without metadata.yaml, and a .db3 that is not SQLite, are refused naming
    the path; without rosbags, the error names the extra to install."""
    with pytest.raises(UsageError, match=r"without a metadata.yaml: not a rosbag2"):
        bag_to_dataframe(tmp_path, "/imu")
    junk = tmp_path / "junk.db3"
    junk.write_bytes(b"not sqlite" * 100)
    with pytest.raises(UsageError, match=rf"{junk}: not a readable rosbag2 recording"):
        info(junk)
    monkeypatch.setitem(sys.modules, "rosbags.rosbag2", None)
    with pytest.raises(UsageError, match=r"pip install 'roslibpy-lite\[rosbag2\]'"):
        bag_to_dataframe(recordings["sqlite3"], "/imu")
    with pytest.raises(UsageError, match=r"the rosbag2 extra"):
        list(read(recordings["db3"]))
    with pytest.raises(UsageError) as refused:
        info(recordings["db3"])
    assert str(refused.value) == _rosbag2.MISSING


def test_a_db3_without_definitions_takes_them_from_msgs_or_names_the_type(
        tmp_path: Path, recordings: dict[str, Path]) -> None:
    """A .db3 from before rosbag2 stored message definitions (its message_definitions table
    empty) reads with msgs' own definitions, the same table; a topic of a type msgs does
    not know either is refused naming the topic and the type, and the others still read."""
    old = tmp_path / "old.db3"
    shutil.copy(recordings["db3"], old)
    with contextlib.closing(sqlite3.connect(old)) as db, db:
        db.execute("DELETE FROM message_definitions")
    pd.testing.assert_frame_equal(bag_to_dataframe(old, "/imu"),
                                  bag_to_dataframe(recordings["reference"], "/imu"))
    with contextlib.closing(sqlite3.connect(old)) as db, db:
        db.execute("UPDATE topics SET type = 'robot_x/msg/Secret' WHERE name = '/note'")
    assert len(list(read(old, ["/imu"]))) == 600  # the other topics still read
    with pytest.raises(UsageError, match=r"/note's type robot_x/msg/Secret has no ros2msg "
                                         r"definition in the recording, and msgs does not"):
        list(read(old, ["/note"]))


def test_a_whole_compressed_file_that_unpacks_past_the_bound_is_refused_first(
        tmp_path: Path, recordings: dict[str, Path]) -> None:
    """A recording compressed as whole files whose .db3.zstd unpacks to 256 MiB from a few
    KB (a zstd stream stating no size, as a file compressor writes it) is refused naming
    the file, its size and the limit, before rosbags writes it out."""
    bomb = tmp_path / "run_file"
    shutil.copytree(recordings["sqlite3-per-file"], bomb)
    packed = bomb / "run_file.db3.zstd"
    with packed.open("wb") as out, zstandard.ZstdCompressor().stream_writer(out) as z:
        for _ in range(256):
            z.write(bytes(1 << 20))
    size = packed.stat().st_size
    assert size < 100_000
    limit = _bounds.chunk_limit(size)
    with pytest.raises(UsageError, match=rf"{packed} unpacks to more than {limit} bytes "
                                         rf"from {size}"):
        info(bomb)
