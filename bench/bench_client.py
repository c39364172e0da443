"""Benchmark of the roslibpy_lite client, printed as JSON (asserts nothing about time).

Run: ``python bench/bench_client.py [--seconds 1.0] [--e2e]``.

Receive path (one core, no network): frames are fed straight into the
client's receive path (``Client._receive``: decode with protocol.py, parse the
op, dispatch by topic, buffer or call back), as the reader task does for each
websocket frame:

- ``small_*``: ``std_msgs/Int32`` publishes, to a sync callback, to an
  ``async for`` reader, and to a typed (``msgs``) subscription;
- ``imu_json``: a ``sensor_msgs/Imu`` (about 700 bytes of JSON);
- ``image_*``: one 640x480 rgb8 ``sensor_msgs/Image`` (921,600 data bytes)
  as a CBOR binary frame and as JSON (base64), into dicts and into typed
  ``Image`` instances.

With ``--e2e`` it also starts a bridge (``python -m bridge_server``) and an
rclpy publisher process, and measures what arrives over the real websocket:
small messages as fast as the publisher can send them, 640x480 rgb8
images with ``compression="cbor"``, and one client publishing small
messages as fast as it can to another client through the bridge.
"""

from __future__ import annotations

import argparse
import asyncio
import base64
import contextlib
import json
import os
import platform
import re
import subprocess
import sys
import time
from collections.abc import Callable
from typing import Any

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import cbor2  # noqa: E402

import roslibpy_lite  # noqa: E402
from msgs.sensor_msgs.msg import Image  # noqa: E402
from msgs.std_msgs.msg import Int32  # noqa: E402
from roslibpy_lite import Client  # noqa: E402

W, H = 640, 480


def _imu() -> dict[str, Any]:
    cov = [0.01, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.01]
    return {
        "header": {"stamp": {"sec": 1700000000, "nanosec": 123456789}, "frame_id": "imu_link"},
        "orientation": {"x": 0.001, "y": -0.002, "z": 0.7071, "w": 0.7071},
        "orientation_covariance": cov,
        "angular_velocity": {"x": 0.01, "y": 0.02, "z": -0.03},
        "angular_velocity_covariance": cov,
        "linear_acceleration": {"x": 0.1, "y": -0.05, "z": 9.81},
        "linear_acceleration_covariance": cov,
    }


def _image_msg(data: Any) -> dict[str, Any]:
    return {
        "header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "camera"},
        "height": H, "width": W, "encoding": "rgb8", "is_bigendian": 0, "step": W * 3,
        "data": data,
    }


def _cdr(type_name: str, wire: dict[str, Any]) -> bytes:
    """The CDR bytes rclpy makes of a message given in its JSON form."""
    from rclpy.serialization import serialize_message

    from bridge_server.rclpy_graph import convert
    from bridge_server.rclpy_graph.types import resolve_message

    cls = resolve_message(type_name)
    return bytes(serialize_message(convert.converter_for(cls).from_obj(wire, "msg")))


def _timed(feed: Callable[[int], None], n: int, seconds: float) -> dict[str, float]:
    """Run ``feed(n)`` repeatedly for about ``seconds`` (best of 3 rounds); rate per item."""
    feed(min(n, 100))  # warm up
    best = float("inf")
    rounds = 3
    for _ in range(rounds):
        done = 0
        start = time.perf_counter()
        deadline = start + seconds / rounds
        while True:
            feed(n)
            done += n
            now = time.perf_counter()
            if now >= deadline:
                break
        best = min(best, (now - start) / done)
    return {"per_s": round(1 / best, 1), "us_each": round(best * 1e6, 2)}


async def receive_path(seconds: float) -> dict[str, Any]:
    """Feed frames into an unconnected client's receive path; report items per second."""
    client = Client("ws://127.0.0.1:9")
    results: dict[str, Any] = {}
    small = [json.dumps({"op": "publish", "topic": "/small", "msg": {"data": i}})
             for i in range(1000)]

    count = [0]
    client.subscribe("/small", "std_msgs/msg/Int32", callback=lambda m: count.__setitem__(0, count[0] + 1))

    def feed_small(n: int) -> None:
        receive = client._receive
        for i in range(n):
            receive(small[i % 1000])

    results["small_sync_callback"] = _timed(feed_small, 1000, seconds)

    await client.close()
    client = Client("ws://127.0.0.1:9")
    sub = client.subscribe("/small", "std_msgs/msg/Int32", buffer_size=2000)
    loop_results: list[float] = []
    for _ in range(3):
        start = time.perf_counter()
        done = 0
        deadline = start + seconds / 3
        while time.perf_counter() < deadline:
            receive = client._receive
            for frame in small:
                receive(frame)
            async for _msg in sub:
                if not sub.pending:
                    break
            done += len(small)
        loop_results.append((time.perf_counter() - start) / done)
    best = min(loop_results)
    results["small_async_for"] = {"per_s": round(1 / best, 1), "us_each": round(best * 1e6, 2)}
    await client.close()

    client = Client("ws://127.0.0.1:9")
    typed: list[Int32] = []
    client.subscribe("/small", Int32, callback=typed.append)

    def feed_typed(n: int) -> None:
        receive = client._receive
        for i in range(n):
            receive(small[i % 1000])
        typed.clear()

    results["small_typed_callback"] = _timed(feed_typed, 1000, seconds)

    imu_frame = json.dumps({"op": "publish", "topic": "/imu", "msg": _imu()})
    client.subscribe("/imu", "sensor_msgs/msg/Imu", callback=lambda m: None)

    def feed_imu(n: int) -> None:
        receive = client._receive
        for _ in range(n):
            receive(imu_frame)

    results["imu_json"] = _timed(feed_imu, 500, seconds)
    results["imu_json"]["frame_bytes"] = len(imu_frame)

    # cbor-raw: the CDR bytes rclpy makes, decoded here by msgs.cdr
    imu_raw = cbor2.dumps({"op": "publish", "topic": "/imu_raw",
                           "msg": {"secs": 1, "nsecs": 2, "bytes": _cdr("sensor_msgs/msg/Imu",
                                                                        _imu())}})
    client.subscribe("/imu_raw", "sensor_msgs/msg/Imu", callback=lambda m: None,
                     compression="cbor-raw")

    def feed_imu_raw(n: int) -> None:
        receive = client._receive
        for _ in range(n):
            receive(imu_raw)

    results["imu_cbor_raw"] = _timed(feed_imu_raw, 500, seconds)
    results["imu_cbor_raw"]["frame_bytes"] = len(imu_raw)

    pixels = bytes(range(256)) * (W * H * 3 // 256)
    cbor_frame = cbor2.dumps({"op": "publish", "topic": "/img", "msg": _image_msg(pixels)})
    json_frame = json.dumps({"op": "publish", "topic": "/img",
                             "msg": _image_msg(base64.b64encode(pixels).decode())})
    got: list[Any] = []
    client.subscribe("/img", "sensor_msgs/msg/Image", callback=got.append)
    client.subscribe("/img_typed", Image, callback=got.append)
    typed_cbor = cbor2.dumps({"op": "publish", "topic": "/img_typed", "msg": _image_msg(pixels)})
    typed_json = json_frame.replace('"/img"', '"/img_typed"', 1)
    cdr = _cdr("sensor_msgs/msg/Image", _image_msg(base64.b64encode(pixels).decode()))
    client.subscribe("/img_raw", "sensor_msgs/msg/Image", callback=got.append,
                     compression="cbor-raw")
    client.subscribe("/img_raw_typed", Image, callback=got.append, compression="cbor-raw")
    raw_frame = cbor2.dumps({"op": "publish", "topic": "/img_raw",
                             "msg": {"secs": 1, "nsecs": 2, "bytes": cdr}})
    typed_raw = cbor2.dumps({"op": "publish", "topic": "/img_raw_typed",
                             "msg": {"secs": 1, "nsecs": 2, "bytes": cdr}})
    frames: tuple[tuple[str, str | bytes], ...] = (
        ("image_cbor_dict", cbor_frame), ("image_cbor_typed", typed_cbor),
        ("image_json_dict", json_frame), ("image_json_typed", typed_json),
        ("image_cbor_raw_dict", raw_frame), ("image_cbor_raw_typed", typed_raw),
    )
    for name, image_frame in frames:
        def feed_image(n: int, frame: str | bytes = image_frame) -> None:
            for _ in range(n):
                client._receive(frame)
            got.clear()

        r = _timed(feed_image, 5, seconds)
        r["frame_bytes"] = len(image_frame)
        r["MB_per_s"] = round(r["per_s"] * len(image_frame) / 1e6, 1)
        results[name] = r
    await client.close()
    return results


# --- a websocket peer blasting frames ----------------------------------------------------------

_BLASTER = r"""
import asyncio, json, sys
from websockets.asyncio.server import serve
n = int(sys.argv[1])
frames = [json.dumps({"op": "publish", "topic": "/blast", "msg": {"data": i}}) for i in range(1000)]
async def handler(ws):
    await ws.recv()  # the client's subscribe
    for i in range(n):
        await ws.send(frames[i % 1000])
    await ws.send(json.dumps({"op": "publish", "topic": "/blast_end", "msg": {"data": n}}))
    await ws.wait_closed()
async def main():
    async with serve(handler, "127.0.0.1", 0, compression=None) as server:
        print(server.sockets[0].getsockname()[1], flush=True)
        await asyncio.get_running_loop().create_future()
asyncio.run(main())
"""


async def websocket_path(n: int) -> dict[str, Any]:
    """Receive ``n`` small publishes over a real loopback websocket from a peer process."""
    peer = await asyncio.create_subprocess_exec(
        sys.executable, "-c", _BLASTER, str(n), stdout=asyncio.subprocess.PIPE,
    )
    try:
        assert peer.stdout is not None
        port = int((await peer.stdout.readline()).decode())
        async with roslibpy_lite.connect(f"ws://127.0.0.1:{port}") as ros:
            count = [0]
            end = asyncio.get_running_loop().create_future()
            ros.subscribe("/blast_end", "std_msgs/msg/Int32", callback=end.set_result)
            start = time.perf_counter()
            ros.subscribe("/blast", "std_msgs/msg/Int32",
                          callback=lambda m: count.__setitem__(0, count[0] + 1))
            await asyncio.wait_for(end, 120)
            elapsed = time.perf_counter() - start
        return {"ws_small": {"received": count[0], "per_s": round(count[0] / elapsed, 1)}}
    finally:
        peer.kill()
        await peer.wait()


# --- end to end through the bridge --------------------------------------------------------------

_ROS_PUBLISHER = r"""
import os, sys, time
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
kind, topic, seconds = sys.argv[1], sys.argv[2], float(sys.argv[3])
rclpy.init()
node = rclpy.create_node("bench_client_pub")
if kind == "small":
    from std_msgs.msg import Int32 as T
    msg = T()
else:
    from sensor_msgs.msg import Image as T
    msg = T(height=480, width=640, encoding="rgb8", step=640 * 3)
    msg.data = bytes(640 * 480 * 3)
pub = node.create_publisher(T, topic, 10)
deadline = time.monotonic() + 30
while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
    time.sleep(0.01)
print("matched", flush=True)
n = 0
end = time.monotonic() + seconds
while time.monotonic() < end:
    if kind == "small":
        msg.data = n
    pub.publish(msg)
    n += 1
    if kind != "small":
        time.sleep(1 / 60)
print("sent", n, flush=True)
node.destroy_node()
rclpy.shutdown()
"""


async def end_to_end(seconds: float) -> dict[str, Any]:
    """Start a bridge and an rclpy publisher; count what the client receives."""
    bridge = subprocess.Popen(
        [sys.executable, "-m", "bridge_server", "--host", "127.0.0.1", "--port", "0"],
        cwd=ROOT, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True,
    )
    try:
        assert bridge.stderr is not None
        port = None
        for line in bridge.stderr:
            m = re.search(r"listening on ws://[\d.]+:(\d+)", line)
            if m:
                port = int(m.group(1))
                break
        if port is None:
            raise RuntimeError("the bridge did not start")
        url = f"ws://127.0.0.1:{port}"
        results: dict[str, Any] = {}
        async with roslibpy_lite.connect(url) as ros:
            for kind, type_name, compression in (
                ("small", "std_msgs/msg/Int32", "none"),
                ("image", "sensor_msgs/msg/Image", "cbor"),
            ):
                topic = f"/bench_{kind}"
                received = [0, 0.0, 0.0]

                def on_msg(_msg: Any, received: list[Any] = received) -> None:
                    now = time.perf_counter()
                    if received[0] == 0:
                        received[1] = now
                    received[0] += 1
                    received[2] = now

                sub = ros.subscribe(topic, type_name, callback=on_msg, compression=compression,
                                    queue_length=1000 if kind == "small" else 2)
                pub = await asyncio.create_subprocess_exec(
                    sys.executable, "-c", _ROS_PUBLISHER, kind, topic, str(seconds),
                    stdout=asyncio.subprocess.PIPE,
                )
                out, _ = await pub.communicate()
                sent = int(out.decode().split("sent")[-1].strip() or 0)
                await asyncio.sleep(0.5)  # let the last messages arrive (bench only)
                await sub.close()
                n, first, last = received
                span = last - first if n > 1 else float("nan")
                results[f"e2e_{kind}"] = {
                    "sent": sent,
                    "received": n,
                    "received_per_s": round((n - 1) / span, 1) if n > 1 else 0.0,
                    "not_delivered": sent - n,
                }
            results["e2e_client_to_client"] = await _client_loop(ros, url, seconds)
        return results
    finally:
        bridge.terminate()
        bridge.wait(10)
        if bridge.stderr is not None:
            bridge.stderr.close()


async def _client_loop(ros: Client, url: str, seconds: float) -> dict[str, Any]:
    """One client publishes small messages as fast as it can; another receives them via ROS."""
    topic = "/bench_loop"
    count = [0]
    done = asyncio.Event()
    total = [0]

    def on_msg(msg: Any) -> None:
        count[0] += 1
        if msg["data"] == -1:
            done.set()

    async with roslibpy_lite.connect(url) as sender:
        pub = await sender.advertise(topic, "std_msgs/msg/Int32")
        sub = ros.subscribe(topic, "std_msgs/msg/Int32", callback=on_msg, queue_length=1000)
        probe = asyncio.get_running_loop().time() + 15
        while count[0] == 0 and asyncio.get_running_loop().time() < probe:
            await pub.publish({"data": 0})
            await asyncio.sleep(0.05)  # bench only: wait for ROS discovery
        count[0] = 0
        start = time.perf_counter()
        end = start + seconds
        n = 0
        while time.perf_counter() < end:
            for _ in range(100):
                await pub.publish({"data": n})
                n += 1
            await asyncio.sleep(0)
        publish_time = time.perf_counter() - start
        await pub.publish({"data": -1})
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(done.wait(), 10)
        elapsed = time.perf_counter() - start
        total[0] = n
        await sub.close()
    return {
        "published": total[0],
        "publish_per_s": round(total[0] / publish_time, 1),
        "received": count[0],
        "received_per_s": round(count[0] / elapsed, 1),
    }


async def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=1.0)
    parser.add_argument("--e2e", action="store_true", help="also measure through a real bridge")
    args = parser.parse_args()
    report: dict[str, Any] = {
        "python": platform.python_version(),
        "machine": platform.machine(),
        "receive_path": await receive_path(args.seconds),
        "websocket": await websocket_path(int(100_000 * args.seconds)),
    }
    if args.e2e:
        report["end_to_end"] = await end_to_end(max(args.seconds, 3.0))
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    asyncio.run(main())
