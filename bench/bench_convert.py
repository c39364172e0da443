"""Micro-benchmark of bridge_server.rclpy_graph.convert: conversions per second, printed as JSON.

Run: ``python bench/bench_convert.py [--seconds 0.5] [--no-tune]``. Each case
runs for about ``--seconds`` (best of three short rounds, the machine is
shared) and reports operations per second and microseconds per operation.
By default it calls ``tune_allocator()`` first, as the bridge does. It asserts
nothing about time.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from collections.abc import Callable
from typing import Any

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from bridge_server.rclpy_graph.convert import (
    converter_for,
    encode_publish_cbor,
    encode_publish_cbor_raw,
    encode_publish_json,
    serialize,
    tune_allocator,
)


def _rate(fn: Callable[[], Any], seconds: float, rounds: int = 3) -> dict[str, float]:
    """Best of ``rounds`` runs of about ``seconds / rounds`` each (the machine is shared)."""
    fn()  # warm up (compiles the converter)
    best = min((_run(fn, seconds / rounds) for _ in range(rounds)), key=lambda r: r["us_per_op"])
    return best


def _run(fn: Callable[[], Any], seconds: float) -> dict[str, float]:
    """Call ``fn`` repeatedly for about ``seconds``; return ops/s and us/op."""
    n = 0
    batch = 1
    start = time.perf_counter()
    deadline = start + seconds
    while True:
        for _ in range(batch):
            fn()
        n += batch
        now = time.perf_counter()
        if now >= deadline:
            break
        batch = min(batch * 2, 4096)
    elapsed = time.perf_counter() - start
    return {"ops_per_s": round(n / elapsed, 1), "us_per_op": round(elapsed / n * 1e6, 2)}


def main() -> None:
    """Run every case and print one JSON object."""
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=0.5, help="time per case")
    ap.add_argument(
        "--no-tune", action="store_true", help="skip tune_allocator() (glibc malloc defaults)"
    )
    args = ap.parse_args()
    s: float = args.seconds
    tuned = False if args.no_tune else tune_allocator()

    from geometry_msgs.msg import PoseStamped, Twist
    from nav_msgs.msg import OccupancyGrid, Odometry
    from sensor_msgs.msg import Image, LaserScan
    from std_msgs.msg import String

    string_msg = String(data="hello world")
    string_conv = converter_for(String)

    img = Image(height=480, width=640, encoding="rgb8", step=640 * 3)
    img.header.frame_id = "camera"
    img.data = bytes(range(256)) * (640 * 480 * 3 // 256)
    img_conv = converter_for(Image)
    img_cdr = serialize(img)

    twist_conv = converter_for(Twist)
    twist_obj = {"linear": {"x": 0.5, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 1}}
    string_obj = {"data": "hello world"}
    pose_conv = converter_for(PoseStamped)
    pose_obj = {
        "header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "map"},
        "pose": {
            "position": {"x": 1.0, "y": 2.0, "z": 3.0},
            "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
        },
    }
    img_json_text = encode_publish_json("/camera", img_conv.to_json(img))
    odom = Odometry(child_frame_id="base_link")
    odom.pose.pose.position.x = 1.25
    odom.pose.covariance[0] = 0.01
    odom_conv = converter_for(Odometry)
    scan = LaserScan(ranges=[1.5 + i / 1000 for i in range(720)], angle_increment=0.00872)
    scan_conv = converter_for(LaserScan)
    grid = OccupancyGrid()
    grid.info.width = grid.info.height = 1000
    grid.data = [-1, 0, 0, 100, 0, 0, 0] * (1_000_000 // 7) + [0] * (1_000_000 % 7)
    grid_conv = converter_for(OccupancyGrid)

    cases: dict[str, Callable[[], Any]] = {
        "string_to_json": lambda: string_conv.to_json(string_msg),
        "string_to_publish_json": lambda: encode_publish_json(
            "/chatter", string_conv.to_json(string_msg)
        ),
        "string_to_publish_cbor": lambda: encode_publish_cbor("/chatter", string_msg, string_conv),
        "image_640x480_rgb8_to_publish_json": lambda: encode_publish_json(
            "/camera", img_conv.to_json(img)
        ),
        "image_640x480_rgb8_to_publish_cbor": lambda: encode_publish_cbor(
            "/camera", img, img_conv
        ),
        "image_640x480_rgb8_to_publish_cbor_raw": lambda: encode_publish_cbor_raw(
            "/camera", img_cdr, 1_700_000_000_123_456_789
        ),
        "odometry_to_publish_json": lambda: encode_publish_json(
            "/odom", odom_conv.to_json(odom)
        ),
        "odometry_to_publish_cbor": lambda: encode_publish_cbor("/odom", odom, odom_conv),
        "laserscan_720_to_publish_json": lambda: encode_publish_json(
            "/scan", scan_conv.to_json(scan)
        ),
        "laserscan_720_to_publish_cbor": lambda: encode_publish_cbor("/scan", scan, scan_conv),
        "occupancy_grid_1000x1000_to_publish_json": lambda: encode_publish_json(
            "/map", grid_conv.to_json(grid)
        ),
        "occupancy_grid_1000x1000_to_publish_cbor": lambda: encode_publish_cbor(
            "/map", grid, grid_conv
        ),
        "string_from_obj": lambda: string_conv.from_obj(string_obj),
        "twist_from_obj": lambda: twist_conv.from_obj(twist_obj),
        "pose_stamped_from_obj": lambda: pose_conv.from_obj(pose_obj),
        "image_640x480_rgb8_from_json_text": lambda: img_conv.from_obj(
            json.loads(img_json_text)["msg"]
        ),
    }
    results = {name: _rate(fn, s) for name, fn in cases.items()}
    print(
        json.dumps(
            {
                "bench": "convert",
                "python": platform.python_version(),
                "seconds_per_case": s,
                "allocator_tuned": tuned,
                "results": results,
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
