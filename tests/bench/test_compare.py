"""``python -m bench --compare``: the table and its flags on fixed inputs, and one run end to end."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from bench.compare import Row, dependency_set, render, rows, unmet

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize(
    ("better", "this", "rev", "flag"),
    [
        ("higher", [90, 95, 100], [120, 125, 130], "WORSE"),  # 30 worse, spread 10
        ("higher", [100, 110, 120], [105, 115, 125], ""),  # 5 worse, spread 20
        ("higher", [120, 125, 130], [90, 95, 100], ""),  # better
        ("lower", [1.5, 1.6, 1.7], [1.0, 1.1, 1.2], "WORSE"),  # 0.5 ms slower, spread 0.2
        ("lower", [1.0, 1.1, 1.2], [1.5, 1.6, 1.7], ""),
        ("lower", [1.0, 1.1, 1.9], [1.0, 1.05, 1.1], ""),  # median 0.05 worse, spread 0.9
        ("higher", [99], [100], "WORSE"),  # one round: no spread, any loss is flagged
        ("info", [10, 11, 12], [500, 510, 520], ""),  # the ROS ceiling: shown, never flagged
        ("higher", [None, None], [1.0, 2.0], "missing"),  # this tree's scenario failed
        ("higher", [1.0, None, 3.0], [None, None, None], ""),  # nothing to compare with
    ],
)
def test_flag(better: str, this: list[float | None], rev: list[float | None], flag: str) -> None:
    """A figure is flagged when its median is worse than REV's by more than either side's range."""
    assert Row("f", better, this, rev).flag == flag


def _image(json_fps: float, ceiling: float) -> dict[str, Any]:
    side = {"frames_per_s": json_fps, "bridge_cpu_ms_per_frame": 5.0}
    return {"scenario": "image", "ros_ceiling": {"frames_per_s": ceiling},
            "json": side, "cbor": side, "cbor-raw": side}


def test_rows_from_results() -> None:
    """Rows hold each round's figure per side; a failed scenario's figures are None."""
    this: list[dict[str, dict[str, Any]]] = [{"image": _image(100.0, 700.0), "latency": {"p50_ms": 0.3, "p99_ms": 0.5}},
            {"image": {"scenario": "image", "error": "RuntimeError: boom"},
             "latency": {"p50_ms": 0.4, "p99_ms": 0.6}}]
    rev = [{"image": _image(200.0, 710.0), "latency": {"p50_ms": 0.3, "p99_ms": 0.5}},
           {"image": _image(210.0, 690.0)}]
    table = {r.figure: r for r in rows(["image", "latency"], this, rev)}
    json_fps = table["image json frames/s"]
    assert (json_fps.this, json_fps.rev, json_fps.flag) == ([100.0, None], [200.0, 210.0], "WORSE")
    assert table["image ROS ceiling frames/s"].rev == [710.0, 690.0]
    assert table["image ROS ceiling frames/s"].flag == ""
    assert table["latency p99 ms"].rev == [0.5, None]
    text = render(list(table.values()), "main~1")
    line = next(x for x in text.splitlines() if x.startswith("image json frames/s"))
    assert line.split() == ["image", "json", "frames/s", "higher", "100", "(1", "failed)",
                            "200", "..", "210", "WORSE"]


PYPROJECT = """
[project]
name = "x"
version = "{version}"
requires-python = ">=3.11"
dependencies = [{deps}]
[project.optional-dependencies]
bridge = ["ros-rclpy==7.1.6", "cbor2>=5.6"]
"""


def test_dependency_set() -> None:
    """The venv is shared when only order or non-dependency fields differ, not when a pin does."""
    base = dependency_set(PYPROJECT.format(version="1", deps='"a>=1", "b"'))
    assert dependency_set(PYPROJECT.format(version="2", deps='"b", "a>=1"')) == base
    assert dependency_set(PYPROJECT.format(version="1", deps='"a>=2", "b"')) != base
    extra = PYPROJECT.replace('"cbor2>=5.6"', '"cbor2>=5.7"')
    assert dependency_set(extra.format(version="1", deps='"a>=1", "b"')) != base


def test_compare_head_end_to_end(tmp_path: Path) -> None:
    """``--compare HEAD`` builds HEAD's worktree, runs each side's own code, writes the table."""
    if subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True).returncode:
        pytest.skip("not a git checkout")
    out = tmp_path / "table.json"
    env = dict(os.environ, BENCH_CACHE_DIR=str(tmp_path / "cache"))
    done = subprocess.run(
        [sys.executable, "-m", "bench", "--compare", "HEAD", "--scenario", "client_service",
         "--repeat", "1", "--quick", "--domain", os.environ["ROS_DOMAIN_ID"],
         "--compare-json", str(out)],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=110,
    )
    try:
        assert done.returncode == 0, done.stderr
        table = json.loads(out.read_text())
        tree = tmp_path / "cache" / "trees" / table["rev_sha"]
        assert "this venv" in done.stderr  # HEAD declares this tree's dependencies
        assert [r["figure"] for r in table["rows"]] == [
            "service (client server) p50 ms", "service (client server) p99 ms",
            "service (client server) calls/s, 16 in flight",
            "service (client server) bridge CPU us/call"]
        for r in table["rows"]:
            assert all(isinstance(v, float) and v > 0 for v in r["this"] + r["rev"]), r
        (this,), (rev,) = table["runs"]["this"], table["runs"]["rev"]
        assert this["summary"]["code"]["root"] == str(ROOT)
        assert rev["summary"]["code"]["root"] == str(tree)
        assert rev["summary"]["code"]["roslibpy_lite"].startswith(str(tree))
        assert "service (client server) p50 ms" in done.stdout
    finally:
        subprocess.run(["git", "worktree", "remove", "--force", str(tmp_path / "cache" / "trees"
                        / subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, text=True,
                                         capture_output=True).stdout.strip())],
                       cwd=ROOT, capture_output=True)


def test_unmet_requirements() -> None:
    """This venv is kept for REV when it meets REV's pins; a pin it cannot meet is named."""
    from importlib.metadata import version

    have = version("websockets")
    assert unmet([f"websockets=={have}", "pytest>=1", 'nothing-here; python_version < "3"']) == []
    assert unmet(["websockets<1", "no-such-package-c29"]) == [
        f"websockets<1 (have {have})", "no-such-package-c29"]


@pytest.mark.parametrize(
    ("args", "says"),
    [(["--compare", "no-such-revision-c29"], "--compare 'no-such-revision-c29': not a revision"),
     (["--compare", "HEAD", "--repeat", "0"], "--repeat 0: give 1 or more rounds")],
)
def test_bad_compare_arguments(args: list[str], says: str, tmp_path: Path) -> None:
    """A revision git does not know, or no rounds, is refused with what was wrong."""
    env = dict(os.environ, BENCH_CACHE_DIR=str(tmp_path))
    done = subprocess.run([sys.executable, "-m", "bench", *args], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=60)
    assert done.returncode != 0
    assert says in done.stderr
    assert not (tmp_path / "trees").exists()
