"""Recordings as tables: ``roslibpy_lite.data.bag_to_dataframe`` against rosbags and
mcap-ros2-support, on the same files.

Run: ``python -m bench.dataframe [--seconds 20] [--imu-seconds 600] [--dir DIR] [--keep]``.
Writes (or reuses, in ``--dir``) two MCAP files as our recorder writes them (zstd chunks of
256 KiB, ROS 2 profile, CDR): ``imu.mcap``, ``--imu-seconds`` of a 200 Hz
``sensor_msgs/Imu`` (600 s: 120,000 rows, 5.5 MB), and ``mixed.mcap``, ``--seconds`` of the
same IMU beside a 30 Hz 640x480 rgb8 camera; then ``imu_db3/``, the IMU's messages as a
rosbag2 directory of one ``.db3`` file (SQLite3 storage, written by rosbags). Each topic
is loaded into a pandas DataFrame with and without a field list, by each reader in a
fresh process (mcap-ros2-support reads no .db3):

- ``ours``: ``bag_to_dataframe(path, topic, fields)``, one call.
- ``rosbags``: rosbags' ``AnyReader``, each message deserialized and its fields gathered
  into the same columns and time index (rosbags 0.11 has no ``get_dataframe`` any more;
  this is the glue a user writes).
- ``mcap_ros2``: mcap's reader with mcap-ros2-support's decoder, the same glue.

The IMU's field list is two columns (``angular_velocity.x``, ``.z``); the camera's is the
header and the image's shape, not the pixels (what a table of frames is for); without a
list, every field (the camera's table then holds every frame's pixels). Reported per case:
seconds and CPU seconds (reading and building the table, after the imports; the CPU figure
is the steadier on a shared machine), peak RSS and its rise over the process's RSS after
the imports, rows and columns; then a table of CPU seconds side by side. Printed as JSON.
It asserts nothing about time.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

IMU, CAMERA = "/bench_imu", "/bench_camera"
FIELDS: dict[str, list[str]] = {
    IMU: ["angular_velocity.x", "angular_velocity.z"],
    CAMERA: ["header", "height", "width", "encoding", "step"],
}
CASES = [("imu", IMU), ("mixed", IMU), ("mixed", CAMERA), ("imu_db3", IMU)]
"""(file, topic) pairs, each read with its field list and without."""


def write_recording(path: Path, seconds: float, imu_hz: float = 200.0,
                    camera_hz: float = 30.0) -> dict[str, int]:
    """The file: ``seconds`` of IMU and camera messages in log-time order; their counts."""
    import numpy as np
    from mcap.writer import CompressionType, Writer

    from msgs import cdr
    from msgs.dynamic import full_text
    from msgs.sensor_msgs.msg import Image, Imu
    from roslibpy_lite.bag._mcap import ROS2_PROFILE, SCHEMA_ENCODING

    rng = np.random.default_rng(0)
    # A camera-like picture: smooth gradients plus sensor noise (zstd gains a little).
    base = (np.add.outer(np.arange(480), np.arange(640)) % 256).astype(np.uint8)
    start_ns = 1_700_000_000 * 10**9
    events: list[tuple[int, str]] = [(round(i * 1e9 / imu_hz), IMU)
                                     for i in range(round(seconds * imu_hz))]
    events += [(round(i * 1e9 / camera_hz), CAMERA) for i in range(round(seconds * camera_hz))]
    events.sort()
    counts = {IMU: 0, CAMERA: 0}
    with path.open("wb") as f:
        writer = Writer(f, chunk_size=256 * 1024, compression=CompressionType.ZSTD)
        writer.start(profile=ROS2_PROFILE, library="roslibpy-lite bench")
        channels: dict[str, int] = {}
        for topic, cls in ((IMU, Imu), (CAMERA, Image)):
            schema = writer.register_schema(cls._type, SCHEMA_ENCODING,
                                            full_text(cls._type).encode())
            channels[topic] = writer.register_channel(topic, "cdr", schema)
        for offset, topic in events:
            t = start_ns + offset
            msg: Any
            if topic == IMU:
                msg = Imu()
                msg.linear_acceleration.z = 9.81 + float(rng.normal(0, 0.05))
                msg.angular_velocity.z = float(rng.normal(0, 0.01))
                msg.orientation.w = 1.0
                msg.header.frame_id = "imu_link"
            else:
                noise = rng.integers(0, 8, (480, 640), dtype=np.uint8)
                pixels = np.repeat((base + noise)[:, :, None], 3, axis=2)
                msg = Image(height=480, width=640, encoding="rgb8", step=640 * 3,
                            data=pixels.tobytes())
                msg.header.frame_id = "camera"
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(t, 10**9)
            writer.add_message(channels[topic], log_time=t, publish_time=t,
                               data=cdr.encode(msg), sequence=counts[topic])
            counts[topic] += 1
        writer.finish()  # type: ignore[no-untyped-call]
    return counts


def write_db3(folder: Path, mcap_path: Path) -> int:
    """The messages of ``mcap_path`` as a rosbag2 directory of one .db3 file (as rosbag2's
    SQLite3 storage lays it out), written by rosbags; how many."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    from roslibpy_lite.bag import read

    store = get_typestore(Stores.ROS2_JAZZY)
    count = 0
    with Writer(folder, version=9) as writer:
        conns: dict[str, Any] = {}
        for msg in read(mcap_path):
            conn = conns.get(msg.topic)
            if conn is None:
                conn = conns[msg.topic] = writer.add_connection(msg.topic, msg.type_name,
                                                                typestore=store)
            writer.write(conn, msg.log_time_ns, msg.data)
            count += 1
    return count


def _ours(path: str, topic: str, fields: list[str] | None) -> Any:
    from roslibpy_lite.data import bag_to_dataframe

    return bag_to_dataframe(path, topic, fields)


def _flat(prefix: str, value: Any, out: dict[str, Any], names: Any) -> None:
    """The glue: a decoded message's fields under dotted names, ``names(value)`` listing a
    message's fields (None for a leaf)."""
    fields = names(value)
    if fields is None:
        out[prefix] = value
        return
    for name in fields:
        _flat(f"{prefix}.{name}" if prefix else name, getattr(value, name), out, names)


def _table(messages: Any, fields: list[str] | None, names: Any) -> Any:
    """The glue's DataFrame of decoded messages, indexed by their header stamps."""
    import pandas as pd

    rows, stamps = [], []
    for msg in messages:
        row: dict[str, Any] = {}
        if fields is None:
            _flat("", msg, row, names)
        else:
            for name in fields:
                _flat(name, _dig(msg, name), row, names)
        rows.append(row)
        stamps.append(msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec)
    frame = pd.DataFrame(rows)
    frame.index = pd.to_datetime(stamps, unit="ns", utc=True).rename("time")
    return frame


def _rosbags(path: str, topic: str, fields: list[str] | None) -> Any:
    from rosbags.highlevel import AnyReader

    def names(value: Any) -> Any:
        found = getattr(value, "__dataclass_fields__", None)
        if found is None or value.__class__.__name__ == "ndarray":
            return None
        return [name for name in found if name != "__msgtype__"]

    with AnyReader([Path(path)]) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        return _table((reader.deserialize(raw, conn.msgtype)
                       for conn, _t, raw in reader.messages(connections=conns)), fields, names)


def _mcap_ros2(path: str, topic: str, fields: list[str] | None) -> Any:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    def names(value: Any) -> Any:
        return None if isinstance(value, list | bytes | str) else getattr(value, "__slots__",
                                                                          None)

    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return _table((decoded for _s, _c, _m, decoded in
                       reader.iter_decoded_messages(topics=[topic])), fields, names)


def _dig(msg: Any, dotted: str) -> Any:
    for part in dotted.split("."):
        msg = getattr(msg, part)
    return msg


READERS = {"ours": _ours, "rosbags": _rosbags, "mcap_ros2": _mcap_ros2}


def _child(reader: str, path: str, topic: str, fields: str) -> None:
    """One case in this (fresh) process: import first, then time and measure the load."""
    import mcap  # noqa: F401  - imports are not the load
    import mcap_ros2.decoder  # noqa: F401
    import pandas  # noqa: F401
    import rosbags.highlevel  # noqa: F401

    import roslibpy_lite.data  # noqa: F401

    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0, cpu0 = time.perf_counter(), time.process_time()
    frame = READERS[reader](path, topic, json.loads(fields))
    seconds, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    print(json.dumps({"seconds": round(seconds, 2), "cpu_s": round(cpu, 2),
                      "peak_rss_mb": round(peak / 1024, 1),
                      "rise_mb": round((peak - before) / 1024, 1), "rows": len(frame),
                      "columns": len(frame.columns)}))


def main() -> None:
    """Write the files (unless there), run each reader on each case, print JSON."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=20.0,
                    help="length of the mixed camera and IMU recording")
    ap.add_argument("--imu-seconds", type=float, default=600.0,
                    help="length of the IMU recording (200 Hz)")
    ap.add_argument("--dir", type=Path, help="use (or make) the files in this directory")
    ap.add_argument("--keep", action="store_true", help="keep the files made here")
    ap.add_argument("--readers", nargs="+", default=list(READERS), choices=list(READERS))
    ap.add_argument("--child", nargs=4, metavar=("READER", "PATH", "TOPIC", "FIELDS"),
                    help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        _child(*args.child)
        return
    folder: Path = args.dir or Path(tempfile.mkdtemp(prefix="bench-df-"))
    folder.mkdir(parents=True, exist_ok=True)
    files = {"imu": (folder / "imu.mcap", args.imu_seconds, 0.0),
             "mixed": (folder / "mixed.mcap", args.seconds, 30.0)}
    result: dict[str, Any] = {"scenario": "dataframe", "python": platform.python_version()}
    for kind, (path, seconds, camera_hz) in files.items():
        if not path.exists():
            t0 = time.perf_counter()
            counts = write_recording(path, seconds, camera_hz=camera_hz)
            result[f"{kind}_messages"] = counts
            result[f"{kind}_write_s"] = round(time.perf_counter() - t0, 1)
        result[f"{kind}_mb"] = round(path.stat().st_size / 2**20, 1)
    db3 = folder / "imu_db3"
    if not db3.exists():
        result["imu_db3_messages"] = write_db3(db3, files["imu"][0])
    result["imu_db3_mb"] = round((db3 / "imu_db3.db3").stat().st_size / 2**20, 1)
    paths = {kind: spec[0] for kind, spec in files.items()} | {"imu_db3": db3}
    cases: dict[str, Any] = {}
    for kind, topic in CASES:
        for fields in (FIELDS[topic], None):
            label = f"{kind} {topic.removeprefix('/bench_')} " + (
                f"{len(fields)} fields" if fields else "all fields")
            for reader in args.readers:
                if kind == "imu_db3" and reader == "mcap_ros2":
                    continue
                out = subprocess.run(
                    [sys.executable, "-m", "bench.dataframe", "--child", reader,
                     str(paths[kind]), topic, json.dumps(fields)],
                    capture_output=True, text=True, check=False,
                    cwd=Path(__file__).resolve().parent.parent, env=dict(os.environ))
                cases.setdefault(label, {})[reader] = (
                    json.loads(out.stdout) if out.returncode == 0
                    else {"error": out.stderr.strip().splitlines()[-1:]})
    result["cases"] = cases
    if args.dir is None and not args.keep:
        shutil.rmtree(folder)
    print(json.dumps(result, indent=2))
    print(_side_by_side(cases, args.readers), file=sys.stderr)


def _side_by_side(cases: dict[str, Any], readers: list[str]) -> str:
    """CPU seconds of each case, a column per reader (wall seconds in brackets)."""
    lines = [f"{'case':34} " + " ".join(f"{r:>16}" for r in readers)]
    for label, by in cases.items():
        cells = []
        for r in readers:
            got = by.get(r)
            cells.append(f"{'-':>16}" if got is None  # a reader that does not read the file
                         else f"{got['cpu_s']:>7.2f} ({got['seconds']:>6.2f})" if "cpu_s" in got
                         else f"{'error':>16}")
        lines.append(f"{label:34} " + " ".join(cells))
    return "\n".join(lines)


if __name__ == "__main__":
    main()
