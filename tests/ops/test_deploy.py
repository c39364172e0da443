"""deploy/: the systemd unit passes systemd-analyze, the Dockerfile runs the real entry point."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from tests.helpers import ROOT, ros_env

DEPLOY = ROOT / "deploy"
UNIT = DEPLOY / "roslibpy-lite-bridge.service"
DOCKERFILE = DEPLOY / "Dockerfile"


def _unit_sections(text: str) -> dict[str, dict[str, list[str]]]:
    sections: dict[str, dict[str, list[str]]] = {}
    current: dict[str, list[str]] | None = None
    for raw in text.splitlines():
        line = raw.strip()
        if not line or line.startswith(("#", ";")):
            continue
        if m := re.fullmatch(r"\[(\w+)\]", line):
            current = sections.setdefault(m[1], {})
            continue
        assert current is not None, f"a key outside any section: {line!r}"
        key, sep, val = line.partition("=")
        assert sep, f"not a key=value line: {line!r}"
        current.setdefault(key.strip(), []).append(val.strip())
    return sections


def _bridge_flags() -> set[str]:
    out = subprocess.run([sys.executable, "-m", "bridge_server", "--help"], cwd=ROOT,
                         env=ros_env(), capture_output=True, text=True, timeout=60, check=True)
    return set(re.findall(r"(--[a-z][a-z-]+)", out.stdout))


def test_unit_has_what_a_service_needs() -> None:
    """The unit names the bridge's entry point with real flags, restarts on failure, and installs."""
    unit = _unit_sections(UNIT.read_text())
    service = unit["Service"]
    exec_start = service["ExecStart"][0].split()
    assert exec_start[0].endswith("/roslibpy-lite-bridge")
    flags = {a for a in exec_start[1:] if a.startswith("--")}
    assert flags <= _bridge_flags(), flags - _bridge_flags()
    assert service["Restart"] == ["on-failure"]
    assert service["KillSignal"] == ["SIGTERM"]
    assert any(e.startswith("ROS_DOMAIN_ID=") for e in service["Environment"])
    assert unit["Install"]["WantedBy"] == ["multi-user.target"]
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts["roslibpy-lite-bridge"] == "bridge_server.__main__:main"


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="systemd-analyze missing")
def test_unit_passes_systemd_analyze_verify(tmp_path: Path) -> None:
    """systemd-analyze verify accepts the unit (pointed at this checkout's entry point)."""
    entry = Path(sys.executable).parent / "roslibpy-lite-bridge"
    text = UNIT.read_text().replace("/opt/roslibpy-lite/.venv/bin/roslibpy-lite-bridge",
                                    str(entry))
    unit = tmp_path / UNIT.name
    unit.write_text(text)
    res = subprocess.run(["systemd-analyze", "verify", str(unit)], capture_output=True,
                         text=True, timeout=60)
    complaints = [ln for ln in (res.stdout + res.stderr).splitlines() if UNIT.name in ln]
    assert res.returncode == 0 and not complaints, res.stdout + res.stderr


def _instructions(text: str) -> list[tuple[str, str]]:
    joined = re.sub(r"\\\n", " ", text)
    out = []
    for line in joined.splitlines():
        line = line.strip()
        if line and not line.startswith("#"):
            word, _, rest = line.partition(" ")
            out.append((word.upper(), rest.strip()))
    return out


def test_dockerfile_structure_and_command_match_the_entry_point() -> None:
    """FROM first, sources copied exist, a non-root user, a /readyz health check, and
    ENTRYPOINT + CMD parse with the bridge's own argument parser."""
    from bridge_server.__main__ import parse_args

    steps = _instructions(DOCKERFILE.read_text())
    words = [w for w, _ in steps]
    assert words[0] == "FROM" and "python:3.11" in steps[0][1]
    for word, rest in steps:
        if word == "COPY":
            for src in rest.split()[:-1]:
                assert (ROOT / src).exists(), f"COPY {src}: no such path in the repository"
    users = [rest for w, rest in steps if w == "USER"]
    assert users and users[-1] not in ("root", "0")
    assert any(w == "RUN" and '".[bridge]"' in rest for w, rest in steps)
    health = next(rest for w, rest in steps if w == "HEALTHCHECK")
    assert "/readyz" in health
    entry = json.loads(next(rest for w, rest in steps if w == "ENTRYPOINT"))
    cmd = json.loads(next(rest for w, rest in steps if w == "CMD"))
    assert entry == ["roslibpy-lite-bridge"]
    flags = {a for a in cmd if a.startswith("--")}
    assert flags <= _bridge_flags(), flags - _bridge_flags()
    args = parse_args(cmd)
    assert (args.host, args.port, args.workers) == ("0.0.0.0", 9090, 2)
    assert "EXPOSE" in words and ("EXPOSE", "9090") in steps
