"""CPU per operation of the client's, the recorder's and the session's hot paths, measured in one
process: no ROS graph and no sockets (``python -m bench.inproc``; ``--compare REV`` for an A/B).

The end-to-end scenarios measure rates and CPU of processes that share two cores with the ROS
side, the clients and whatever else runs on the machine: there a difference of 5-10 % hides
in the run-to-run spread. These cases run the product's own code on prepared input and count
the process's CPU time only, so they resolve a few percent on a loaded machine:

- ``recorder_imu_us``: a ``cbor-raw`` publish frame of an IMU's size (324 bytes of CDR) handed
  to the client's websocket transport (``receive``: frame decoding, the op's parsing, routing,
  the raw subscription) and on into the MCAP recorder's writer, as ``roslibpy-lite bag
  record`` takes each message (the socket and websockets' framing aside);
- ``recorder_image_us``: the same with a 640x480 rgb8 frame (921,654 bytes);
- ``image_json_us`` and ``image_cbor_us``: the bridge's ``publish`` op of one such Image
  received as CDR, as JSON text and as CBOR (``Incoming.encoded``: the message's encoding and
  its envelope), made once per message whatever the number of subscribers;
- ``mock_call_us``: a client-served ``std_srvs/SetBool`` called through ``MockRos``: the client,
  the bridge's session and the in-memory graph, everything of ``client_service`` but rclpy and
  the sockets;
- ``mock_publish_us``: a ``std_msgs/String`` published and delivered to a subscription's
  callback through ``MockRos``.

Each case runs ``--rounds`` rounds of a fixed count of operations and keeps the least CPU per
operation (the round least disturbed); then one more round under ``cProfile`` counts the
Python function calls per operation, a figure that load does not move at all (two trees that
make the same calls do the same work, whatever their times say on a busy machine). ``--compare REV`` runs each side in a process of its own
with its tree first on ``sys.path`` (REV checked out as for ``python -m bench --compare``),
alternating A B B A for ``--repeat`` rounds, and prints the minimum of each side and the ratio.
The cases reach into the recorder and the bridge's topic module by their private names, which
both sides must have (they do from 6e1e82a on). Nothing here asserts anything about time.
"""

from __future__ import annotations

import argparse
import asyncio
import cProfile
import importlib
import json
import os
import pstats
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

IMU_BYTES = 324
"""The CDR size of a ``sensor_msgs/Imu`` with a short frame id."""
IMAGE_SHAPE = (480, 640, 3)
"""The ``image`` scenario's frame: 640x480 rgb8."""
CASES = ("recorder_imu_us", "recorder_image_us", "image_json_us", "image_cbor_us",
         "mock_call_us", "mock_publish_us")


def _least(rounds: int, count: int, op: Callable[[], Any]) -> float:
    """The least process CPU per call of ``op`` over ``rounds`` rounds of ``count`` calls (us)."""
    best = float("inf")
    for _ in range(rounds):
        t0 = time.process_time()
        for _ in range(count):
            op()
        best = min(best, (time.process_time() - t0) / count)
    return 1e6 * best


class _Calls:
    """Python function calls made while open, per operation: a count no load disturbs (the
    profiler's own time is not measured, only its count of calls)."""

    def __init__(self) -> None:
        self._profile = cProfile.Profile()

    def __enter__(self) -> _Calls:
        self._profile.enable()
        return self

    def __exit__(self, *exc: object) -> None:
        self._profile.disable()

    def per(self, count: int) -> float:
        """Calls per operation, of ``count`` operations."""
        return pstats.Stats(self._profile).total_calls / count  # type: ignore[attr-defined,no-any-return]


async def _recorder(rounds: int, size: int, count: int) -> tuple[float, float]:
    """CPU (us) and Python calls per cbor-raw frame of ``size`` bytes through the client into
    the recorder."""
    import cbor2

    from msgs.dynamic import full_text
    from roslibpy_lite.bag.recorder import Recorder
    from roslibpy_lite.client import Client

    topic, type_name = "/bench_inproc", "sensor_msgs/msg/Imu"
    ros = Client("ws://127.0.0.1:9")  # never connected: frames go straight to receive()
    with tempfile.TemporaryDirectory(prefix="bench-inproc-") as tmp:
        rec = Recorder(ros, Path(tmp) / "run.mcap", topics={topic: type_name})
        rec._open(rec.path)
        rec._types[topic] = (type_name, full_text(type_name))
        rec._qos[topic] = ""
        rec._register(topic)
        sub = ros.subscribe(topic, type_name, raw=True, buffer_size=10_000)
        sub.on_message(rec._on_message)
        payload = os.urandom(size)
        frames = [cbor2.dumps({"op": "publish", "topic": topic,
                               "msg": {"bytes": payload, "secs": 1, "nsecs": i}})
                  for i in range(8)]
        receive = ros._transport.receive  # type: ignore[attr-defined]
        turn = iter(range(1 << 62))
        us = _least(rounds, count, lambda: receive(frames[next(turn) & 7]))
        with _Calls() as calls:
            for _ in range(count):
                receive(frames[next(turn) & 7])
        if rec.stats.messages != (rounds + 1) * count:
            raise RuntimeError(f"the recorder wrote {rec.stats.messages} of "
                               f"{(rounds + 1) * count} messages")
        rec._close()
        return us, calls.per(count)


def _image_encodings(rounds: int) -> dict[str, tuple[float, float]]:
    """CPU (us) and Python calls of the bridge's JSON and CBOR publish ops of one 640x480 Image
    from its CDR."""
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import Image

    from bridge_server.rclpy_graph import convert

    try:  # where the bridge keeps its received message (moved in issue 51's split)
        topics: Any = importlib.import_module("bridge_server.rclpy_graph.topics")
        incoming = topics.Incoming
    except (ImportError, AttributeError):
        incoming = importlib.import_module("bridge_server.rclpy_graph.node").Incoming
    msg = Image()
    msg.height, msg.width, _ = IMAGE_SHAPE
    msg.encoding, msg.step = "rgb8", IMAGE_SHAPE[1] * IMAGE_SHAPE[2]
    msg.data = os.urandom(IMAGE_SHAPE[0] * IMAGE_SHAPE[1] * IMAGE_SHAPE[2])
    msg.header.frame_id = "1 0"
    data = serialize_message(msg)
    conv = convert.converter_for(Image)
    cases: dict[str, Callable[[], Any]] = {
        "image_json_us": lambda: incoming("/i", data, conv, 0).encoded("none"),
        "image_cbor_us": lambda: incoming("/i", data, conv, 0).encoded("cbor")}
    out: dict[str, tuple[float, float]] = {}
    for case, op in cases.items():
        us = _least(rounds, 20, op)
        with _Calls() as calls:
            op()
        out[case] = (us, calls.per(1))
    return out


async def _mock(rounds: int, count: int) -> dict[str, tuple[float, float]]:
    """CPU (us) and Python calls per client-served call and per published message through
    MockRos."""
    from roslibpy_lite.mock import MockRos

    ros = MockRos()
    ros.advertise_service("/bench_inproc", "std_srvs/srv/SetBool",
                          lambda req: {"success": req["data"], "message": "ok"})
    got = [0]
    ros.subscribe("/bench_inproc", "std_msgs/msg/String").on_message(
        lambda _msg: got.__setitem__(0, got[0] + 1))
    pub = ros.advertise("/bench_inproc", "std_msgs/msg/String")
    calls, published = float("inf"), float("inf")
    for _ in range(rounds):
        t0 = time.process_time()
        for _ in range(count):
            await ros.call_service("/bench_inproc", "std_srvs/srv/SetBool", {"data": True})
        calls = min(calls, (time.process_time() - t0) / count)
        t0 = time.process_time()
        for _ in range(count):
            await pub.publish({"data": "x"})
        await ros.drain()
        published = min(published, (time.process_time() - t0) / count)
    with _Calls() as call_calls:
        for _ in range(count):
            await ros.call_service("/bench_inproc", "std_srvs/srv/SetBool", {"data": True})
    with _Calls() as publish_calls:
        for _ in range(count):
            await pub.publish({"data": "x"})
        await ros.drain()
    if got[0] != (rounds + 1) * count:
        raise RuntimeError(f"the subscription got {got[0]} of {(rounds + 1) * count} messages")
    return {"mock_call_us": (1e6 * calls, call_calls.per(count)),
            "mock_publish_us": (1e6 * published, publish_calls.per(count))}


async def measure(rounds: int) -> dict[str, float]:
    """Every case on the code this process imports (see the module's docstring): the CPU per
    operation (``<case>``) and the Python calls per operation (``<case>_calls``)."""
    out = {"recorder_imu_us": await _recorder(rounds, IMU_BYTES, 5000),
           "recorder_image_us": await _recorder(
               rounds, IMAGE_SHAPE[0] * IMAGE_SHAPE[1] * IMAGE_SHAPE[2], 40)}
    out.update(_image_encodings(rounds))
    out.update(await _mock(rounds, 1000))
    flat: dict[str, float] = {}
    for case, (us, calls) in out.items():
        flat[case] = round(us, 2)
        flat[case.removesuffix("_us") + "_calls"] = round(calls, 1)
    return flat


def _side(root: Path, rounds: int) -> dict[str, float]:
    """One measurement in a process of its own, with ``root``'s code first on the path."""
    done = subprocess.run([sys.executable, __file__, "--measure", "--root", str(root),
                           "--rounds", str(rounds)], cwd=root, capture_output=True, text=True)
    if done.returncode:
        raise SystemExit(f"bench.inproc on {root} failed:\n{done.stderr[-2000:]}")
    result: dict[str, float] = json.loads(done.stdout.strip().splitlines()[-1])
    return result


def _compare(rev: str, repeat: int, rounds: int) -> int:
    from bench.compare import resolve, worktree
    from bench.harness import ROOT

    sha = resolve(rev)
    sides = {"this tree": ROOT, sha[:9]: worktree(sha)}
    got: dict[str, list[dict[str, float]]] = {name: [] for name in sides}
    for i in range(repeat):
        order = list(sides) if i % 2 == 0 else list(sides)[::-1]
        for name in order:
            got[name].append(_side(sides[name], rounds))
            print(f"round {i + 1}: {name} done", file=sys.stderr)
    this, that = list(sides)
    print(f"{'case: CPU us per operation (least of the rounds)':<50} {this:>10} {that:>10}  ratio"
          f"   Python calls per op: {this:>9} {that:>9}")
    for case in CASES:
        a = min(r[case] for r in got[this])
        b = min(r[case] for r in got[that])
        calls = case.removesuffix("_us") + "_calls"
        print(f"{case:<50} {a:>10.2f} {b:>10.2f}  {a / b:5.3f}   {'':<21}"
              f"{got[this][0][calls]:>9.1f} {got[that][0][calls]:>9.1f}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """``python -m bench.inproc [--compare REV]`` (see the module's docstring)."""
    p = argparse.ArgumentParser(prog="python -m bench.inproc", description=__doc__.split("\n")[0])
    p.add_argument("--compare", metavar="REV", help="A/B: this tree against git revision REV")
    p.add_argument("--repeat", type=int, default=3, help="--compare: rounds of each side")
    p.add_argument("--rounds", type=int, default=5, help="rounds of each case in one process")
    p.add_argument("--measure", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--root", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.compare:
        return _compare(args.compare, args.repeat, args.rounds)
    if args.root:  # run as a script: its folder (bench/) off the path, the side's tree first
        here = Path(__file__).resolve().parent
        sys.path[:] = [args.root, *(p for p in sys.path if Path(p or ".").resolve() != here)]
    print(json.dumps(asyncio.run(measure(args.rounds))))
    return 0


if __name__ == "__main__":
    sys.exit(main())
