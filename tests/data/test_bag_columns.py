"""bag_to_dataframe's column reader (fields straight from the CDR bytes) against the
message-by-message table, on files written by our recorder, by rosbags and by mcap_ros2."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.writer import CompressionType, IndexType, Writer

import roslibpy_lite
import roslibpy_lite.data as data
from msgs import cdr
from msgs.cdr_columns import leaf_names
from msgs.dynamic import full_text
from msgs.runtime import Message
from msgs.sensor_msgs.msg import Image, Imu, JointState, PointCloud2
from msgs.test_msgs.msg import (
    Arrays,
    BasicTypes,
    BoundedSequences,
    Strings,
    UnboundedSequences,
    WStrings,
)
from roslibpy_lite import MockRos
from roslibpy_lite.bag import Recorder
from roslibpy_lite.bag._mcap import ROS2_PROFILE, SCHEMA_ENCODING
from roslibpy_lite.data import bag_to_dataframe
from roslibpy_lite.handles import Publisher
from tests.msgs.test_cdr import _message

T0 = 1_700_000_000 * 10**9


def _general(monkeypatch: pytest.MonkeyPatch, *args: Any) -> pd.DataFrame:
    """The table as read before the column reader: a message at a time, decoded and flattened."""
    with monkeypatch.context() as m:
        m.setattr(data, "_bag_columns", lambda *_: None)
        return bag_to_dataframe(*args)


def _same(monkeypatch: pytest.MonkeyPatch, path: Path, topic: str,
          fields: list[str] | None) -> pd.DataFrame:
    """The column reader reads the file (it does not hand it to the general path) and gives
    the general path's table: columns, dtypes, values, time index."""
    fast = data._bag_columns(path, topic, fields)
    assert fast is not None, "the column reader passed the file on"
    pd.testing.assert_frame_equal(fast, _general(monkeypatch, path, topic, fields))
    pd.testing.assert_frame_equal(bag_to_dataframe(path, topic, fields), fast)
    return fast


def _write(path: Path, messages: list[tuple[str, int, Message | bytes, str]],
           chunk_size: int = 1024, index: IndexType = IndexType.ALL) -> None:
    """An MCAP file as our recorder lays it out: (topic, log time, message or raw bytes,
    type); small chunks, so that a topic spans several."""
    with path.open("wb") as f:
        writer = Writer(f, chunk_size=chunk_size, compression=CompressionType.ZSTD,
                        index_types=index)
        writer.start(profile=ROS2_PROFILE, library="test")
        channels: dict[str, int] = {}
        for topic, t, msg, type_name in messages:
            if topic not in channels:
                schema = writer.register_schema(type_name, SCHEMA_ENCODING,
                                                full_text(type_name).encode())
                channels[topic] = writer.register_channel(topic, "cdr", schema)
            raw = msg if isinstance(msg, bytes) else cdr.encode(msg)
            writer.add_message(channels[topic], log_time=t, publish_time=t, data=raw)
        writer.finish()  # type: ignore[no-untyped-call]


RICH = [Imu, Image, PointCloud2, JointState, Arrays, BasicTypes, BoundedSequences,
        UnboundedSequences, Strings, WStrings]


@pytest.mark.parametrize("cls", RICH, ids=lambda c: c._type)
@settings(max_examples=8, deadline=None, suppress_health_check=[
    HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.function_scoped_fixture])
@given(draw=st.data())
def test_random_messages_give_the_same_table(cls: type[Message], draw: st.DataObject,
                                             tmp_path_factory: pytest.TempPathFactory,
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """Random messages of types with every kind of field, at log times out of order and
    tied, spread over chunks: every field, a random pick of fields and a nested message's
    fields each give the general path's table."""
    msgs = draw.draw(st.lists(_message(cls), min_size=1, max_size=6))
    times = draw.draw(st.lists(st.integers(0, 3), min_size=len(msgs), max_size=len(msgs)))
    path = tmp_path_factory.mktemp("rich") / "rich.mcap"
    _write(path, [("/x", T0 + t, m, cls._type) for m, t in zip(msgs, times, strict=True)],
           chunk_size=draw.draw(st.sampled_from([1, 4096])))
    names = [name for name, _ in leaf_names(cls)]
    picked = draw.draw(st.lists(st.sampled_from(names), min_size=1, max_size=4))
    for fields in (None, picked, sorted({n.split(".")[0] for n in names})[:2]):
        _same(monkeypatch, path, "/x", fields)


async def test_our_recorders_file_gives_the_same_table(tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """A file our recorder wrote (on MockRos): IMU messages whose frame ids differ in length
    (so their numbers sit at different offsets), a camera and a joint state (strings and
    sequences before the fields asked for) read as the general path reads them."""
    path = tmp_path / "ours.mcap"
    topics = {"/imu": "sensor_msgs/msg/Imu", "/camera": "sensor_msgs/msg/Image",
              "/joints": "sensor_msgs/msg/JointState"}
    async with MockRos() as ros, Recorder(ros, path, topics=topics, max_messages=3 * 40) as rec:
        pubs: dict[str, Publisher[Any]] = {
            t: await ros.advertise(t, ty) for t, ty in topics.items()}
        for i in range(40):
            imu = Imu()
            imu.header.stamp.sec, imu.header.frame_id = 100 + i, "imu" + "_" * (i % 7)
            imu.angular_velocity.z, imu.orientation_covariance[4] = 0.5 * i, -i
            await pubs["/imu"].publish(imu)
            await pubs["/camera"].publish(Image(
                height=2, width=3, encoding="rgb8" if i % 2 else "mono8", step=9,
                data=bytes(range(i, i + 18))))
            await pubs["/joints"].publish(JointState(
                name=[f"j{k}" for k in range(i % 4)], position=[0.1 * i] * (i % 4),
                velocity=[float(i)]))
        await rec.wait(10)
    imu = _same(monkeypatch, path, "/imu", ["angular_velocity.z", "orientation_covariance"])
    assert imu["angular_velocity.z"].iloc[3] == 1.5 and imu["orientation_covariance"].iloc[3][4] == -3
    assert imu.index[5] == pd.Timestamp(105, unit="s", tz="UTC")
    _same(monkeypatch, path, "/imu", None)
    _same(monkeypatch, path, "/imu", ["header"])
    camera = _same(monkeypatch, path, "/camera", ["encoding", "width", "data"])
    assert list(camera["encoding"][:2]) == ["mono8", "rgb8"]
    _same(monkeypatch, path, "/camera", None)
    joints = _same(monkeypatch, path, "/joints", ["velocity", "position", "header.stamp"])
    assert joints["position"].iloc[3] == pytest.approx([0.3] * 3)
    _same(monkeypatch, path, "/joints", None)


def test_a_file_rosbags_wrote_gives_the_same_table(tmp_path: Path,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """A rosbag2 MCAP that rosbags wrote, its messages serialized by rosbags: IMU and a
    PoseArray (a sequence of nested messages after a header) as the general path reads them."""
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as BagWriter
    from rosbags.typesys import Stores, get_typestore

    from msgs.geometry_msgs.msg import Pose, PoseArray

    store = get_typestore(Stores.ROS2_JAZZY)
    bag = tmp_path / "theirs"
    with BagWriter(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        imu_conn = writer.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=store)
        poses_conn = writer.add_connection("/poses", "geometry_msgs/msg/PoseArray",
                                           typestore=store)
        for i in range(30):
            imu = Imu()
            imu.header.stamp.nanosec, imu.header.frame_id = i * 1000, "base" * (i % 3)
            imu.linear_acceleration.x = i / 7
            theirs = store.deserialize_cdr(cdr.encode(imu), "sensor_msgs/msg/Imu")
            writer.write(imu_conn, T0 + i, store.serialize_cdr(theirs, "sensor_msgs/msg/Imu"))
            poses = PoseArray(poses=[Pose() for _ in range(i % 3)])
            poses.header.frame_id = "map"
            for k, pose in enumerate(poses.poses):
                pose.position.y = i + k
            theirs = store.deserialize_cdr(cdr.encode(poses), "geometry_msgs/msg/PoseArray")
            writer.write(poses_conn, T0 + i,
                         store.serialize_cdr(theirs, "geometry_msgs/msg/PoseArray"))
    (path,) = bag.glob("*.mcap")
    imu = _same(monkeypatch, path, "/imu", ["linear_acceleration.x", "header.frame_id"])
    assert imu["linear_acceleration.x"].iloc[14] == 2.0 and imu["header.frame_id"].iloc[2] == "basebase"
    _same(monkeypatch, path, "/imu", None)
    poses = _same(monkeypatch, path, "/poses", ["poses"])
    assert [p.position.y for p in poses["poses"].iloc[5]] == [5.0, 6.0]
    _same(monkeypatch, path, "/poses", None)


def test_a_file_mcap_ros2_wrote_gives_the_same_table(tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """A file mcap_ros2's writer wrote (its own serializer): IMU, and a type with strings and
    sequences before the numbers asked for (BasicTypes after Strings in a robot's type)."""
    from mcap_ros2.writer import Writer as Ros2Writer

    path = tmp_path / "mcap_ros2.mcap"
    robot = "string label\nfloat64[] values\nuint8[4] tag\nint64 count\nbool ok\nstring note"
    roslibpy_lite.define_type("robot_msgs/msg/Sample", robot)
    with path.open("wb") as f:
        writer = Ros2Writer(f)
        imu = writer.register_msgdef("sensor_msgs/msg/Imu", full_text("sensor_msgs/msg/Imu"))
        sample = writer.register_msgdef("robot_msgs/msg/Sample", robot)
        for i in range(25):
            writer.write_message("/imu", imu, {
                "header": {"stamp": {"sec": i, "nanosec": 7}, "frame_id": "é" * (i % 4)},
                "angular_velocity": {"x": 0.25 * i, "y": 0.0, "z": -0.5}},
                log_time=T0 + i, publish_time=T0 + i)
            writer.write_message("/sample", sample, {
                "label": "x" * i, "values": [float(k) for k in range(i % 5)],
                "tag": [i, 0, 255, 1], "count": -(2**40) * i, "ok": i % 2 == 0,
                "note": "n"}, log_time=T0 + 10 * i, publish_time=T0)
        writer.finish()  # type: ignore[no-untyped-call]
    frame = _same(monkeypatch, path, "/imu", ["header.frame_id", "angular_velocity"])
    assert frame["header.frame_id"].iloc[3] == "ééé"
    _same(monkeypatch, path, "/imu", None)
    samples = _same(monkeypatch, path, "/sample", ["count", "tag", "ok"])
    assert samples["count"].dtype == np.int64 and samples["tag"].iloc[2] == bytes([2, 0, 255, 1])
    assert samples.index[1] == pd.Timestamp(T0 + 10, unit="ns", tz="UTC")  # no header
    _same(monkeypatch, path, "/sample", None)


def _broken() -> Iterator[tuple[str, int, Message | bytes, str]]:
    """50 IMU and 50 joint states, the 37th of each cut short by a few bytes."""
    for i in range(50):
        imu, joints = Imu(), JointState(name=["a", "b"], position=[1.0, 2.0])
        imu.header.frame_id = "imu"
        yield "/imu", T0 + i, (imu if i != 37 else cdr.encode(imu)[:-5]), Imu._type
        yield "/joints", T0 + i, (joints if i != 37 else cdr.encode(joints)[:-3]), \
            JointState._type


@pytest.mark.parametrize("topic, field", [("/imu", "linear_acceleration_covariance"),
                                          ("/joints", "effort")])
def test_a_truncated_message_is_named_by_topic_and_place(tmp_path: Path, topic: str,
                                                         field: str) -> None:
    """A message cut short fails the table with CdrError naming the file, the topic, the
    message's place and the field it ends in, for fixed layouts and for rows alike."""
    path = tmp_path / "cut.mcap"
    _write(path, list(_broken()))
    with pytest.raises(cdr.CdrError, match=rf"^{path}: message 37 on {topic}: \S+: cannot "
                                           rf"decode field '{field}' from CDR: (truncated|claims)"):
        bag_to_dataframe(path, topic, None if topic == "/imu" else ["name"])


def test_a_count_past_the_end_is_refused_before_anything_is_read(tmp_path: Path) -> None:
    """A sequence claiming 2^32-1 elements in a few bytes fails at once (no allocation of
    that size), naming the message; a chunk that does not decompress names its offset."""
    path = tmp_path / "claims.mcap"
    joints = bytearray(cdr.encode(JointState()))
    joints[-16:-12] = b"\xff\xff\xff\xff"  # name: the first sequence, after the header
    _write(path, [("/joints", T0 + i, bytes(joints) if i == 3 else JointState(), JointState._type)
                  for i in range(10)])
    with pytest.raises(cdr.CdrError, match=r"message 3 on /joints: .*'name'.*claims 4294967295"):
        bag_to_dataframe(path, "/joints", ["velocity"])
    good = tmp_path / "good.mcap"
    _write(good, [("/imu", T0 + i, Imu(), Imu._type) for i in range(200)], chunk_size=4096)
    raw = bytearray(good.read_bytes())
    at = raw.index(b"zstd") + 4 + 8 + 20
    raw[at:at + 40] = bytes(40)
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(raw))
    with pytest.raises(roslibpy_lite.UsageError, match=r"the chunk at byte \d+ cannot be read"):
        bag_to_dataframe(bad, "/imu", ["header.stamp.sec"])


def test_a_recording_cut_short_is_read_message_by_message(tmp_path: Path,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """A file without its summary (a killed recorder's) is handed to the general path,
    which reads it up to its last whole chunk: the same table as before."""
    path = tmp_path / "whole.mcap"
    _write(path, [("/imu", T0 + i, Imu(), Imu._type) for i in range(100)], chunk_size=2048)
    cut = tmp_path / "cut.mcap"
    raw = path.read_bytes()
    cut.write_bytes(raw[:len(raw) // 2])
    assert data._bag_columns(cut, "/imu", None) is None
    frame = bag_to_dataframe(cut, "/imu", ["header.stamp.nanosec"])
    pd.testing.assert_frame_equal(frame, _general(monkeypatch, cut, "/imu",
                                                  ["header.stamp.nanosec"]))
    assert 0 < len(frame) < 100


def test_chunks_without_message_indexes_are_read_whole(tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """A file whose chunk index does not say which topics a chunk holds (no message
    indexes): every chunk is read, those with none of the topic's messages included."""
    path = tmp_path / "unindexed.mcap"
    messages: list[tuple[str, int, Message | bytes, str]] = []
    for i in range(60):
        imu = Imu()
        imu.header.stamp.sec = i
        messages.append(("/imu", T0 + i, imu, Imu._type) if i % 20 < 5 else
                        ("/joints", T0 + i, JointState(name=["a"] * 8), JointState._type))
    _write(path, messages, chunk_size=512, index=IndexType.CHUNK)
    frame = _same(monkeypatch, path, "/imu", ["header.stamp.sec"])
    assert list(frame["header.stamp.sec"]) == [i for i in range(60) if i % 20 < 5]


def test_the_imu_of_a_camera_file_is_read_without_decompressing_the_frames(
        tmp_path: Path) -> None:
    """Each chunk is decompressed only up to the topic's last message in it (its message
    index says where): the IMU table of a second of 30 Hz 640x480 camera beside a 200 Hz
    IMU peaks below the size of one frame, which follows the IMU messages in its chunk."""
    import tracemalloc

    from bench.dataframe import CAMERA, IMU, write_recording

    path = tmp_path / "mixed.mcap"
    assert write_recording(path, seconds=1.0)[CAMERA] == 30
    tracemalloc.start()
    try:
        frame = bag_to_dataframe(path, IMU, ["linear_acceleration.z"])
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert len(frame) == 200
    one_frame = 640 * 480 * 3
    assert peak < one_frame / 2, f"peak {peak / 2**10:.0f} KiB, a frame is {one_frame / 2**10:.0f}"


def test_a_message_index_claiming_more_than_the_file_is_refused(tmp_path: Path) -> None:
    """A message index whose length claims more bytes than the file holds fails naming its
    chunk, before anything of that size is read."""
    from mcap.reader import make_reader

    path = tmp_path / "index.mcap"
    _write(path, [("/imu", T0 + i, Imu(), Imu._type) for i in range(50)], chunk_size=4096)
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    at = next(iter(summary.chunk_indexes[0].message_index_offsets.values()))
    raw = bytearray(path.read_bytes())
    raw[at + 1:at + 9] = (2**40).to_bytes(8, "little")  # a terabyte
    path.write_bytes(bytes(raw))
    with pytest.raises(roslibpy_lite.UsageError, match=r"the chunk at byte \d+ cannot be read: "
                                                       r"ValueError: no message index at byte"):
        bag_to_dataframe(path, "/imu", ["header.stamp.sec"])
