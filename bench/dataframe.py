"""A recording as a table: ``roslibpy_lite.data.bag_to_dataframe`` against rosbags' reader.

Run: ``python -m bench.dataframe [--seconds 60] [--file run.mcap] [--keep]``. Writes (or
reuses) an MCAP of ``--seconds`` of a 200 Hz ``sensor_msgs/Imu`` and a 30 Hz 640x480 rgb8
camera, as our recorder writes them (zstd chunks of 256 KiB, ROS 2 profile, CDR), then
loads each topic into a pandas DataFrame twice, each time in a fresh process:

- ``ours``: ``bag_to_dataframe(path, topic, fields)``, one call.
- ``rosbags``: rosbags' ``AnyReader`` on the same file, each message deserialized and its
  fields gathered into the same columns and time index (rosbags 0.11 has no
  ``get_dataframe`` any more; this is the glue a user writes).

The IMU table has every field; the camera table the header and the image's shape, not the
pixels (what a table of frames is for), so both readers still read every frame's bytes.
Reported per case: seconds and CPU seconds (reading and building the table, after the
imports; the CPU figure is the steadier on a shared machine), peak RSS
and its rise over the process's RSS after the imports, rows and columns. Printed as one
JSON object. It asserts nothing about time.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

IMU, CAMERA = "/bench_imu", "/bench_camera"
FIELDS: dict[str, list[str] | None] = {
    IMU: None,
    CAMERA: ["header", "height", "width", "encoding", "step"],
}


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


def _ours(path: str, topic: str, fields: list[str] | None) -> Any:
    from roslibpy_lite.data import bag_to_dataframe

    return bag_to_dataframe(path, topic, fields)


def _rosbags(path: str, topic: str, fields: list[str] | None) -> Any:
    import pandas as pd
    from rosbags.highlevel import AnyReader

    def flat(prefix: str, value: Any, out: dict[str, Any]) -> None:
        names = getattr(value, "__dataclass_fields__", None)
        if names is None or value.__class__.__name__ == "ndarray":
            out[prefix] = value
            return
        for name in names:
            if name != "__msgtype__":
                flat(f"{prefix}.{name}" if prefix else name, getattr(value, name), out)

    rows, stamps = [], []
    with AnyReader([Path(path)]) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        for conn, _t, raw in reader.messages(connections=conns):
            msg: Any = reader.deserialize(raw, conn.msgtype)
            row: dict[str, Any] = {}
            if fields is None:
                flat("", msg, row)
            else:
                for name in fields:
                    flat(name, _dig(msg, name), row)
            rows.append(row)
            stamps.append(msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec)
    frame = pd.DataFrame(rows)
    frame.index = pd.to_datetime(stamps, unit="ns", utc=True).rename("time")
    return frame


def _dig(msg: Any, dotted: str) -> Any:
    for part in dotted.split("."):
        msg = getattr(msg, part)
    return msg


READERS = {"ours": _ours, "rosbags": _rosbags}


def _child(reader: str, path: str, topic: str) -> None:
    """One case in this (fresh) process: import first, then time and measure the load."""
    import mcap  # noqa: F401  - imports are not the load
    import pandas  # noqa: F401
    import rosbags.highlevel  # noqa: F401

    import roslibpy_lite.data  # noqa: F401

    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0, cpu0 = time.perf_counter(), time.process_time()
    frame = READERS[reader](path, topic, FIELDS[topic])
    seconds, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    print(json.dumps({"seconds": round(seconds, 2), "cpu_s": round(cpu, 2), "peak_rss_mb": round(peak / 1024, 1),
                      "rise_mb": round((peak - before) / 1024, 1), "rows": len(frame),
                      "columns": len(frame.columns),
                      "table_mb": round(frame.memory_usage(deep=True).sum() / 2**20, 1)}))


def main() -> None:
    """Write the file (unless given), run each reader on each topic, print JSON."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0, help="length of the recording")
    ap.add_argument("--file", type=Path, help="use (or make) this file")
    ap.add_argument("--keep", action="store_true", help="keep the file made here")
    ap.add_argument("--child", nargs=3, metavar=("READER", "PATH", "TOPIC"),
                    help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        _child(*args.child)
        return
    path: Path = args.file or Path(tempfile.mkdtemp(prefix="bench-df-")) / "run.mcap"
    result: dict[str, Any] = {"scenario": "dataframe", "seconds_recorded": args.seconds,
                              "python": platform.python_version()}
    if not path.exists():
        t0 = time.perf_counter()
        result["messages"] = write_recording(path, args.seconds)
        result["write_s"] = round(time.perf_counter() - t0, 1)
    result["file_mb"] = round(path.stat().st_size / 2**20, 1)
    cases: dict[str, Any] = {}
    for topic in (IMU, CAMERA):
        for reader in READERS:
            out = subprocess.run(
                [sys.executable, "-m", "bench.dataframe", "--child", reader, str(path), topic],
                capture_output=True, text=True, check=False,
                cwd=Path(__file__).resolve().parent.parent, env=dict(os.environ))
            cases[f"{topic.removeprefix('/bench_')} {reader}"] = (
                json.loads(out.stdout) if out.returncode == 0
                else {"error": out.stderr.strip().splitlines()[-1:]})
    result["cases"] = cases
    if args.file is None and not args.keep:
        path.unlink()
        path.parent.rmdir()
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
