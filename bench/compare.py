"""``python -m bench --compare REV``: this tree against another git revision, one table.

REV (any revision git knows: ``main~3``, a tag, a sha) is checked out once in a git worktree
under the cache folder (``$BENCH_CACHE_DIR``, default ``~/.cache/roslibpy-lite-bench``):
``trees/<sha>``. Its Python environment is this one when REV's ``pyproject.toml`` declares the
same dependencies (``project.dependencies``, every optional extra, ``requires-python``) as
this tree's, or other ones that this venv's installed packages all meet (REV before a
dependency was added); else a venv of its own, ``venvs/<hash of that set>``, made once with pip
(REV installed with its ``bridge``, ``cbor``, ``cli`` and ``mcap`` extras, and psutil; the
custom interfaces under ``msgs/interfaces`` are not built: no scenario uses them). The output
says which.

Each run is this checkout's harness (``python -m bench --scenario ...`` in a subprocess)
with ``BENCH_CODE_ROOT`` naming the tree whose client and bridge it measures: the scenarios,
the ROS side and the counting are the same code for both, and only the product differs. The
two alternate, ``--repeat`` rounds, this tree first in even rounds and REV first in odd ones
(A B B A ...), so that a machine drifting during the comparison weighs on both.

A figure is flagged when this tree is worse than REV by more than the run-to-run spread:
its median is worse than REV's median by more than the larger of the two sides' ranges
(max - min over the rounds). With one round the ranges are 0 and every worse figure is
flagged; three rounds (the default) or more make the flag mean something. A figure that
REV has and this tree lacks (its scenario failed) is flagged too.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import re
import statistics
import subprocess
import sys
import time
import tomllib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bench.harness import ROOT

COMPARE_SCENARIOS = ["ros_to_client", "ros_to_client_raw", "client_to_ros", "service",
                     "client_service", "latency", "image", "pointcloud", "record"]
"""What ``--compare`` runs unless ``--scenario`` names others: small messages both ways,
services both ways, latency, images, fan-out and recording."""

CAMERA, IMU = "/bench_camera", "/bench_imu"


@dataclass(frozen=True)
class Figure:
    """One number of one scenario's result and which way is better."""

    label: str
    get: Callable[[dict[str, Any]], Any]
    better: str
    """``higher``, ``lower`` or ``info`` (shown, never flagged: the ROS ceiling)."""


def _delivered(r: dict[str, Any]) -> float:
    return 100.0 * float(min(r["per_client"])) / float(max(r["published"], 1))


def _step(steps: list[dict[str, Any]], viewers: int) -> dict[str, Any] | None:
    """The step of a fan-out result with ``viewers`` viewers (``None``: not run)."""
    return next((s for s in steps if s["viewers"] == viewers), None)


def _per_message(part: str, viewers: int) -> Callable[[dict[str, Any]], Any]:
    """The server's CPU per delivered message of one fan-out step."""
    return lambda r: (_step(r[part], viewers) or {}).get("server_cpu_us_per_message")


def _service(prefix: str) -> list[Figure]:
    return [Figure(f"{prefix} p50 ms", lambda r: r["p50_ms"], "lower"),
            Figure(f"{prefix} p99 ms", lambda r: r["p99_ms"], "lower"),
            Figure(f"{prefix} calls/s, 16 in flight", lambda r: r["calls_per_s"], "higher")]


def _image(key: str) -> list[Figure]:
    return [Figure(f"image {key} frames/s", lambda r: r[key]["frames_per_s"], "higher"),
            Figure(f"image {key} bridge ms/frame", lambda r: r[key]["bridge_cpu_ms_per_frame"],
                   "lower")]


def _cloud(key: str) -> list[Figure]:
    return [Figure(f"pointcloud {key} delivered %", lambda r: _delivered(r[key]), "higher"),
            Figure(f"pointcloud {key} bridge CPU %", lambda r: r[key]["bridge_cpu_pct"], "lower"),
            Figure(f"pointcloud {key} bridge RSS peak MB",
                   lambda r: r[key]["bridge_rss_mb"]["peak"], "lower")]


FIGURES: dict[str, list[Figure]] = {
    "ros_to_client": [Figure("ROS->client msg/s at 99 %", lambda r: r["best_rate_99pct"],
                             "higher")],
    "ros_to_client_raw": [Figure("ROS->client cbor-raw msg/s at 99 %",
                                 lambda r: r["best_rate_99pct"], "higher")],
    "client_to_ros": [Figure("client->ROS msg/s at 99 %", lambda r: r["best_rate_99pct"],
                             "higher")],
    "service": _service("service (ROS server)"),
    "client_service": [*_service("service (client server)"),
                       Figure("service (client server) bridge CPU us/call",
                              lambda r: r["bridge_cpu_us_per_call"], "lower")],
    "latency": [Figure("latency p50 ms", lambda r: r["p50_ms"], "lower"),
                Figure("latency p99 ms", lambda r: r["p99_ms"], "lower")],
    "image": [*_image("json"), *_image("cbor"), *_image("cbor-raw"),
              Figure("image ROS ceiling frames/s", lambda r: r["ros_ceiling"]["frames_per_s"],
                     "info")],
    "pointcloud": [*_cloud("cbor"), *_cloud("cbor-raw")],
    "record": [
        Figure("record camera %", lambda r: r["camera_imu"]["topics"][CAMERA]["recorded_pct"],
               "higher"),
        Figure("record IMU %", lambda r: r["camera_imu"]["topics"][IMU]["recorded_pct"],
               "higher"),
        Figure("record recorder CPU %", lambda r: r["camera_imu"]["recorder_cpu_pct"], "lower"),
        Figure("record camera Hz at 99 %", lambda r: r["best_camera_rate_99pct"], "higher"),
    ],
    "fanout": [Figure(f"fanout {part}, {n} viewers: CPU us/message", _per_message(part, n),
                      "lower")
               for part in ("bridge", "relay") for n in (100, 200)]
    + [Figure("fanout camera, 100 viewers of a relay: delivered %",
              lambda r: 100.0 * r["camera_relay"]["delivered_fraction"], "higher"),
       Figure("fanout write floor, 100 sockets: CPU us/send",
              lambda r: r["write_floor_us"]["100"], "info")],
    "relay_imu": [Figure("relay_imu relay CPU us/message",
                         lambda r: r["relay_cpu_us_per_message"], "lower"),
                  Figure("relay_imu delivered %", lambda r: 100.0 * r["delivered_fraction"],
                         "higher")],
    "relay_uplink": [Figure("relay_uplink robot uplink, 10 viewers of a relay: x one viewer's",
                            lambda r: (_step(r["relay"], 10) or {}).get("x_one_viewer"),
                            "lower")],
    "relay_service": [Figure("relay_service through a relay p50 ms",
                             lambda r: r["relay"]["p50_ms"], "lower"),
                      Figure("relay_service through a relay p99 ms",
                             lambda r: r["relay"]["p99_ms"], "lower")],
    "idle_cpu": [Figure("idle bridge CPU %", lambda r: r["connected_pct_of_core"], "lower")],
}
"""The figures of each scenario the table shows (scenarios not here show none)."""


def figures(scenario: str, result: dict[str, Any]) -> dict[str, float | None]:
    """The figures of one scenario's result; ``None`` where it failed or lacks one."""
    out: dict[str, float | None] = {}
    for fig in FIGURES.get(scenario, []):
        value: object = None
        if "error" not in result:
            try:
                value = fig.get(result)
            except (KeyError, TypeError, ValueError, IndexError):
                value = None
        out[fig.label] = None
        if isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value):
            out[fig.label] = float(value)
    return out


@dataclass
class Row:
    """One line of the table: a figure over the rounds, for this tree and for REV."""

    figure: str
    better: str
    this: list[float | None]
    rev: list[float | None]

    @property
    def flag(self) -> str:
        """Why this tree looks worse (see the module docstring), or ``""``."""
        a = [v for v in self.this if v is not None]
        b = [v for v in self.rev if v is not None]
        if self.better == "info" or not b:
            return ""
        if not a:
            return "missing"
        spread = max(max(a) - min(a), max(b) - min(b))
        gap = statistics.median(b) - statistics.median(a)
        if self.better == "lower":
            gap = -gap
        return "WORSE" if gap > spread else ""

    def as_json(self) -> dict[str, Any]:
        """The row for the JSON file."""
        return {"figure": self.figure, "better": self.better, "this": self.this,
                "rev": self.rev, "flag": self.flag}


def rows(scenarios: Sequence[str], this_runs: Sequence[dict[str, dict[str, Any]]],
         rev_runs: Sequence[dict[str, dict[str, Any]]]) -> list[Row]:
    """The table's rows from each side's runs (scenario name -> that run's result)."""
    def per_run(runs: Sequence[dict[str, dict[str, Any]]], name: str) -> list[dict[str, Any]]:
        return [figures(name, run.get(name, {"error": "no result"})) for run in runs]

    out: list[Row] = []
    for name in scenarios:
        this, rev = per_run(this_runs, name), per_run(rev_runs, name)
        out.extend(Row(fig.label, fig.better, [f[fig.label] for f in this],
                       [f[fig.label] for f in rev]) for fig in FIGURES.get(name, []))
    return out


def _span(values: Sequence[float | None]) -> str:
    got = [v for v in values if v is not None]
    if not got:
        return "failed"
    lo, hi = min(got), max(got)
    text = _num(lo) if lo == hi else f"{_num(lo)} .. {_num(hi)}"
    missing = len(values) - len(got)
    return f"{text} ({missing} failed)" if missing else text


def _num(v: float) -> str:
    if v == int(v) and abs(v) >= 100:
        return f"{int(v):,}"
    return f"{v:,.3g}" if abs(v) < 10 else f"{v:,.1f}"


def render(table: Sequence[Row], rev: str) -> str:
    """The table as text: figure, which way is better, this tree's range, REV's, the flag."""
    head = ("figure", "better", "this tree", rev, "flag")
    lines = [(r.figure, r.better, _span(r.this), _span(r.rev), r.flag) for r in table]
    widths = [max(len(str(c)) for c in col) for col in zip(head, *lines, strict=True)]

    def fmt(cols: Sequence[str]) -> str:
        return "  ".join(c.ljust(w) for c, w in zip(cols, widths, strict=True)).rstrip()

    return "\n".join([fmt(head), fmt(["-" * w for w in widths]), *map(fmt, lines)])


# -- the other tree and its environment --------------------------------------------------------


def dependency_set(pyproject: str) -> dict[str, Any]:
    """What a ``pyproject.toml`` asks to be installed: dependencies, each extra, Python."""
    project = tomllib.loads(pyproject).get("project", {})
    return {
        "requires-python": project.get("requires-python"),
        "dependencies": sorted(project.get("dependencies", [])),
        "optional-dependencies": {k: sorted(v) for k, v in
                                  sorted(project.get("optional-dependencies", {}).items())},
    }


def unmet(requirements: Sequence[str]) -> list[str]:
    """Those of ``requirements`` (PEP 508) that this Python's installed packages do not meet
    (a requirement's extras are not followed; one whose marker excludes this Python is met)."""
    from importlib.metadata import PackageNotFoundError, version

    from packaging.requirements import Requirement

    out: list[str] = []
    for text in requirements:
        req = Requirement(text)
        if req.marker is not None and not req.marker.evaluate():
            continue
        try:
            have = version(req.name)
        except PackageNotFoundError:
            out.append(text)
            continue
        if not req.specifier.contains(have, prereleases=True):
            out.append(f"{text} (have {have})")
    return out


REV_EXTRAS = ("bridge", "cbor", "cli", "mcap")
"""The extras a REV's own venv is made with (Jazzy's bridge: one venv holds one ROS 2
distribution, so ``bridge-kilted`` is not among them)."""


def _all_requirements(deps: dict[str, Any]) -> list[str]:
    """The dependencies and those of :data:`REV_EXTRAS`, an extra naming others of the
    project's (``roslibpy-lite[bridge-base]``) followed."""
    out: list[str] = list(deps["dependencies"])
    todo, seen = list(REV_EXTRAS), set[str]()
    while todo:
        extra = todo.pop()
        if extra in seen:
            continue
        seen.add(extra)
        for req in deps["optional-dependencies"].get(extra, []):
            own = re.match(r"roslibpy[-_]lite\[([\w,-]+)\]", req)
            if own:
                todo += own.group(1).split(",")
            else:
                out.append(req)
    return out


def cache_dir() -> Path:
    """Where worktrees and venvs of compared revisions are kept."""
    return Path(os.environ.get("BENCH_CACHE_DIR")
                or Path.home() / ".cache" / "roslibpy-lite-bench").resolve()


def _git(*args: str, cwd: Path = ROOT) -> str:
    done = subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True)
    if done.returncode:
        raise RuntimeError(f"git {' '.join(args)}: {done.stderr.strip()}")
    return done.stdout.strip()


def resolve(rev: str) -> str:
    """The commit ``rev`` names (a clear error if git knows none)."""
    try:
        return _git("rev-parse", "--verify", "--quiet", f"{rev}^{{commit}}")
    except RuntimeError:
        raise SystemExit(f"--compare {rev!r}: not a revision this repository knows") from None


def worktree(sha: str) -> Path:
    """REV's tree: a detached git worktree under the cache folder, made once."""
    path = cache_dir() / "trees" / sha
    if (path / ".git").exists():
        try:
            if _git("rev-parse", "HEAD", cwd=path) == sha:
                return path
        except RuntimeError:
            pass
    _git("worktree", "prune")
    path.parent.mkdir(parents=True, exist_ok=True)
    _git("worktree", "add", "--force", "--detach", str(path), sha)
    return path


@dataclass(frozen=True)
class Side:
    """One side of the comparison: whose code, run by which Python."""

    name: str
    root: Path
    python: str


def environment(sha: str, tree: Path, log: Callable[[str], None]) -> str:
    """The Python that runs REV: this one when the dependency sets match, else REV's own venv."""
    theirs = dependency_set(_git("show", f"{sha}:pyproject.toml"))
    if theirs == dependency_set((ROOT / "pyproject.toml").read_text()):
        log(f"environment: this venv ({sys.prefix}); REV's pyproject.toml declares the same "
            "dependencies")
        return sys.executable
    missing = unmet(_all_requirements(theirs))
    if not missing:
        log(f"environment: this venv ({sys.prefix}); REV's pyproject.toml declares other "
            "dependencies, and this venv meets every one of them")
        return sys.executable
    key = hashlib.sha256(json.dumps(theirs, sort_keys=True).encode()).hexdigest()[:16]
    venv = cache_dir() / "venvs" / key
    python = venv / "bin" / "python"
    stamp = venv / ".ready"
    if stamp.exists():
        log(f"environment: REV's own venv {venv} (this venv does not meet "
            f"{', '.join(missing)}; made before)")
        return str(python)
    log(f"environment: REV's dependencies differ from this tree's and this venv does not meet "
        f"{', '.join(missing)}; making its venv {venv}")
    subprocess.run([sys.executable, "-m", "venv", "--clear", str(venv)], check=True)
    subprocess.run([str(python), "-m", "pip", "install", "-q", "--disable-pip-version-check",
                    f"{tree}[{','.join(REV_EXTRAS)}]", "psutil"], check=True)
    stamp.write_text(sha + "\n")
    return str(python)


@dataclass
class Run:
    """One run of the harness on one side's code."""

    results: dict[str, dict[str, Any]]
    """Scenario name -> its result."""
    summary: dict[str, Any]
    """The harness's last line (with ``code``: whose client and bridge ran)."""


def run_once(side: Side, scenarios: Sequence[str], extra: Sequence[str],
             log: Callable[[str], None]) -> Run:
    """One run of this harness on ``side``'s code."""
    env = dict(os.environ, BENCH_CODE_ROOT=str(side.root))
    t0 = time.monotonic()
    done = subprocess.run([side.python, "-m", "bench", "--scenario", *scenarios, *extra],
                          cwd=ROOT, env=env, capture_output=True, text=True)
    results: dict[str, dict[str, Any]] = {}
    summary: dict[str, Any] = {}
    for line in done.stdout.splitlines():
        if line.startswith("{"):
            try:
                obj = json.loads(line)
            except ValueError:
                continue
            if "scenario" in obj:
                results[obj["scenario"]] = obj
            elif "summary" in obj:
                summary = obj
    failed = [n for n in scenarios if "error" in results.get(n, {"error": ""})]
    log(f"  {side.name}: {time.monotonic() - t0:.0f} s"
        + (f", failed: {', '.join(failed)}" if failed else ""))
    if failed and not results:
        log(done.stderr.strip()[-2000:])
    return Run(results, summary)


def compare(args: argparse.Namespace, scenarios: list[str]) -> int:
    """Build REV, run both sides alternately, print the table and write it as JSON."""
    def log(text: str) -> None:
        print(text, file=sys.stderr, flush=True)

    if args.repeat < 1:
        raise SystemExit(f"--repeat {args.repeat}: give 1 or more rounds")
    sha = resolve(args.compare)
    label = f"{args.compare} ({sha[:9]})" if not sha.startswith(args.compare) else sha[:9]
    tree = worktree(sha)
    log(f"REV {label}: worktree {tree}")
    this = Side("this tree", ROOT, sys.executable)
    rev = Side(label, tree, environment(sha, tree, log))
    extra = ["--domain", str(args.domain), *(["--quick"] if args.quick else []),
             *(["--duration", str(args.duration)] if args.duration is not None else [])]
    runs: dict[str, list[Run]] = {this.name: [], rev.name: []}
    for k in range(args.repeat):
        log(f"round {k + 1} of {args.repeat}")
        for side in (this, rev) if k % 2 == 0 else (rev, this):
            runs[side.name].append(run_once(side, scenarios, extra, log))
    table = rows(scenarios, [r.results for r in runs[this.name]],
                 [r.results for r in runs[rev.name]])
    print(render(table, rev.name), flush=True)
    flagged = sum(bool(r.flag) for r in table)
    print(f"{flagged} of {len(table)} figures flagged (worse by more than the run-to-run "
          f"spread over {args.repeat} round(s); see bench/README.md)", flush=True)
    out = Path(args.compare_json) if args.compare_json else (
        cache_dir() / f"compare-{sha[:12]}-{time.strftime('%Y%m%dT%H%M%S')}.json")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({
        "rev": args.compare, "rev_sha": sha, "this_tree": str(ROOT),
        "rev_python": rev.python, "rounds": args.repeat, "quick": args.quick,
        "scenarios": scenarios, "rows": [r.as_json() for r in table],
        "runs": {"this": [vars(r) for r in runs[this.name]],
                 "rev": [vars(r) for r in runs[rev.name]]},
    }, indent=1))
    print(f"JSON: {out}", flush=True)
    return 0
