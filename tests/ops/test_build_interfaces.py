"""scripts/build-interfaces.sh: a robot's stock interface package, built with the one command,
becomes a type the bridge knows."""

from __future__ import annotations

import asyncio
import os
import subprocess
import sys
from pathlib import Path

import pytest

import roslibpy_lite
from roslibpy_lite.exceptions import StatusError
from tests.helpers import ROOT, BridgeProcess, ros_env

SCRIPT = ROOT / "scripts" / "build-interfaces.sh"
FIXTURES = ROOT / "tests" / "ops" / "fixtures"  # not tests/interfaces: setup.sh builds those


def _build(prefix: Path, *dirs: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["bash", str(SCRIPT), *map(str, dirs)], cwd=ROOT,
                          env=ros_env(VENV=sys.prefix, PREFIX=str(prefix)),
                          capture_output=True, text=True, timeout=600)


async def _round_trip(url: str) -> dict[str, object]:
    async with roslibpy_lite.connect(url) as ros:
        pub = await ros.advertise("/beacon", "beacon_msgs/msg/Beacon", latch=True)
        await pub.publish({"label": "dock", "level": 3})
        async with ros.subscribe("/beacon", "beacon_msgs/msg/Beacon") as sub:
            async for msg in sub:
                return {key: msg[key] for key in ("label", "level")}
    raise AssertionError("no message")


def test_build_interfaces_makes_a_stock_package_known_to_the_bridge(tmp_path: Path) -> None:
    """A folder holding a stock package (no line for the PyPI wheels in its CMakeLists.txt)
    builds with one command; a bridge that sees the result carries its type, one that does
    not refuses it; a second run with nothing changed builds nothing."""
    prefix = tmp_path / "prefix"
    out = _build(prefix, FIXTURES)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "building interface package beacon_msgs" in out.stderr
    again = _build(prefix, FIXTURES)
    assert again.returncode == 0 and again.stderr == "", again.stderr

    site = next(prefix.glob("lib/python3*/site-packages"))
    seen = BridgeProcess(env={"PYTHONPATH": f"{site}:{ROOT}",
                              "AMENT_PREFIX_PATH": f"{prefix}:{sys.prefix}",
                              # (before what the ROS wheels' bootstrapper set in this process)
                              "LD_LIBRARY_PATH": f"{prefix}/lib:{os.environ['LD_LIBRARY_PATH']}"}
                         ).start()
    try:
        assert asyncio.run(_round_trip(seen.url)) == {"label": "dock", "level": 3}
    finally:
        seen.stop()
    unseen = BridgeProcess().start()
    try:
        with pytest.raises(StatusError, match="beacon_msgs"):
            asyncio.run(_round_trip(unseen.url))
    finally:
        unseen.stop()


def test_build_interfaces_names_what_is_wrong(tmp_path: Path) -> None:
    """No folder, or no virtual environment: one line saying so, exit 2, nothing built."""
    out = _build(tmp_path / "prefix", tmp_path / "nope")
    assert out.returncode == 2 and f"{tmp_path / 'nope'}: no such folder" in out.stderr
    bad = subprocess.run(["bash", str(SCRIPT), str(FIXTURES)], cwd=ROOT,
                         env=ros_env(VENV=str(tmp_path)), capture_output=True, text=True,
                         timeout=60)
    assert bad.returncode == 2 and f"no virtual environment at '{tmp_path}'" in bad.stderr
