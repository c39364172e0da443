"""Recording through the bridge (``--scenario record``): ``roslibpy-lite bag record`` in its own
process, as a user runs it, against our bridge and ROS-side publishers in theirs.

- ``camera_imu``: a 640x480 rgb8 camera at 30 Hz and an IMU at 200 Hz for the scenario's
  duration (60 s in a full run, 10 s with ``--quick``). Reported: what was published and
  what the file holds per topic (and any gap in the sequence numbers), the recorder's CPU
  (% of one core, from its process's CPU time over the recording), the bridge's CPU, the
  data rate (message bytes a second), the write rate (MB/s into the file, zstd chunks;
  the pixels are random, as incompressible as a camera's) and the file's size.
- ``ladder``: the camera alone at rising rates (3 s a step, 2 with ``--quick``); the
  highest rate at which the file holds >= 99 % of the frames, and the recorder's CPU at
  each step.

The file is read back with ``roslibpy_lite.bag.read`` (messages decoded from the file's
own schemas). Nothing here asserts anything about time.
"""

from __future__ import annotations

import asyncio
import itertools
import signal
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from bench.harness import CODE_ROOT, Bridge, Ctx, child_env
from bench.profiler import Profiler

__all__ = ["record"]

CAMERA, IMU = "/bench_camera", "/bench_imu"


async def _recording(ctx: Ctx, bridge: Bridge, streams: dict[str, tuple[str, float]],
                     seconds: float, profile: bool = False) -> dict[str, Any]:
    """Record ``streams`` (topic -> (kind, rate)) for ``seconds`` with the CLI; the figures
    (with ``profile``, py-spy's on the recorder beside them)."""
    import psutil

    from roslibpy_lite.bag import read

    path = Path(tempfile.mkdtemp(prefix="bench-bag-")) / "run.mcap"
    recorder = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "roslibpy_lite.cli", "bag", "record", *streams, "-o", str(path),
        "--url", bridge.url, cwd=CODE_ROOT, env=child_env(ctx.domain),
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE)
    publishers = [ctx.ros("publish", "--topic", topic, "--kind", kind, "--rate", str(rate),
                          "--duration", str(seconds), "--depth", "100", "--wait-subs", "1",
                          "--settle", "0.5", "--linger", "2", "--noise")
                  for topic, (kind, rate) in streams.items()]
    try:
        for pub in publishers:
            await pub.start()
        for pub in publishers:  # the recorder's subscriptions reached the bridge
            await pub.event("matched", timeout=60)
        me, them = psutil.Process(recorder.pid), psutil.Process(bridge.pid)
        cpu0 = me.cpu_times()
        bridge0 = them.cpu_times()
        t0 = time.monotonic()
        prof = await Profiler.maybe(profile, recorder.pid, seconds)
        done = [await pub.event("done", timeout=seconds + 60) for pub in publishers]
        await asyncio.sleep(1.0)  # the last messages in flight through the bridge
        cpu1, bridge1 = me.cpu_times(), them.cpu_times()
        wall = time.monotonic() - t0
        recorder.send_signal(signal.SIGINT)
        out, err = await asyncio.wait_for(recorder.communicate(), 60)
        samples = await prof.result() if prof is not None else None
    finally:
        for pub in publishers:
            await pub.close()
        if recorder.returncode is None:
            recorder.kill()
            await recorder.wait()
    got: dict[str, list[int]] = {topic: [] for topic in streams}
    data = 0
    for msg in read(path):
        got[msg.topic].append(int(msg.decode().header.frame_id.split()[0]))  # type: ignore[attr-defined]
        data += len(msg.data)
    size = path.stat().st_size
    topics: dict[str, Any] = {}
    for (topic, (kind, rate)), sent in zip(streams.items(), done, strict=True):
        seqs = got[topic]
        topics[topic] = {
            "kind": kind, "rate_hz": rate, "published": sent["sent"], "recorded": len(seqs),
            "recorded_pct": round(100.0 * len(seqs) / max(sent["sent"], 1), 2),
            "missing": sent["sent"] - len(set(seqs)), "out_of_order": sum(
                1 for a, b in itertools.pairwise(seqs) if b < a),
        }
    path.unlink()
    return {
        "topics": topics,
        "recorder_cpu_pct": round(100.0 * _busy(cpu0, cpu1) / wall, 1),
        "bridge_cpu_pct": round(100.0 * _busy(bridge0, bridge1) / wall, 1),
        "data_mb_per_s": round(data / 1e6 / wall, 2),
        "write_mb_per_s": round(size / 1e6 / wall, 2),
        "file_mb": round(size / 1e6, 1),
        "seconds": round(wall, 1),
        "recorder_exit": recorder.returncode,
        "recorder_said": (out.decode().strip().splitlines() or [""])[-1][:200],
        **({"recorder_stderr": err.decode()[-500:]} if recorder.returncode else {}),
        **({"recorder_profile": samples} if samples is not None else {}),
    }


def _busy(before: Any, after: Any) -> float:
    return float(after.user - before.user + after.system - before.system)


async def record(ctx: Ctx) -> dict[str, Any]:
    """The ``record`` scenario (see the module docstring)."""
    bridge = ctx.bridge()
    await bridge.start()
    try:
        seconds = 10.0 if ctx.quick else 60.0
        camera_imu = await _recording(
            ctx, bridge, {CAMERA: ("image", 30.0), IMU: ("imu", 200.0)}, seconds, ctx.profile)
        ladder: list[dict[str, Any]] = []
        best = 0.0
        for rate in (30.0, 60.0, 120.0, 240.0, 480.0):
            step = await _recording(ctx, bridge, {CAMERA: ("image", rate)},
                                    2.0 if ctx.quick else 3.0)
            cam = step["topics"][CAMERA]
            ladder.append({"rate_hz": rate, "recorded_pct": cam["recorded_pct"],
                           "recorder_cpu_pct": step["recorder_cpu_pct"],
                           "data_mb_per_s": step["data_mb_per_s"]})
            if cam["recorded_pct"] < 99.0:
                break
            best = rate
    finally:
        await bridge.stop()
    return {"camera_imu": camera_imu, "ladder": ladder, "best_camera_rate_99pct": best}
