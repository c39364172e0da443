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


def _unit_command(tmp: Path, port: int, with_log_dirs: bool = True) -> tuple[list[str], dict[str, str]]:
    """The unit's exact ExecStart and Environment, with its files pointed at ``tmp``: the venv
    of this checkout, an auth file and a certificate made here, a free port, this run's
    ROS domain, the directories systemd would make for LogsDirectory/StateDirectory, and the
    HOME a system user without a home directory has under ProtectHome (nothing writable)."""
    import trustme

    from bridge_server.auth import add_principal

    service = _unit_sections(UNIT.read_text())["Service"]
    argv = service["ExecStart"][0].split()
    auth = tmp / "auth.toml"
    token = add_principal(auth, "deploy", "viewer")
    (tmp / "token").write_text(token)
    ca = trustme.CA()
    cert = ca.issue_cert("127.0.0.1")
    cert.cert_chain_pems[0].write_to_path(str(tmp / "server.pem"))
    cert.private_key_pem.write_to_path(str(tmp / "server.key"))
    ca.cert_pem.write_to_path(str(tmp / "ca.pem"))
    swap = {"/opt/roslibpy-lite/.venv/bin/roslibpy-lite-bridge":
            str(Path(sys.executable).parent / "roslibpy-lite-bridge"),
            "/etc/roslibpy-lite/auth.toml": str(auth),
            "/etc/roslibpy-lite/server.pem": str(tmp / "server.pem"),
            "/etc/roslibpy-lite/server.key": str(tmp / "server.key")}
    argv = [swap.get(a, a) for a in argv]
    argv[argv.index("--port") + 1] = str(port)
    env = ros_env()
    env["HOME"] = "/proc/nohome"  # what a home-less system user gets: not writable
    env.pop("ROS_LOG_DIR", None)
    env.pop("ROS_HOME", None)
    dirs = {"%L": tmp / "log", "%S": tmp / "state"}
    for line in service["Environment"]:
        key, _, value = line.partition("=")
        if key == "ROS_DOMAIN_ID":
            continue  # this test run's own domain
        if key in ("ROS_LOG_DIR", "ROS_HOME") and not with_log_dirs:
            continue
        for spec, path in dirs.items():
            if spec in value:
                value = value.replace(spec, str(path))
                (path / "roslibpy-lite-bridge").mkdir(parents=True, exist_ok=True)
        env[key] = value
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"  # tests stay on loopback
    return argv, env


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_unit_command_serves_as_a_user_without_a_home(tmp_path: Path) -> None:
    """The unit's exact ExecStart, with its Environment and log directories, starts the bridge
    when HOME is not writable (a system user without a home), serves wss with a token, and
    ROS writes its logs to LogsDirectory; without those directories rclpy dies as reported."""
    import asyncio
    import signal
    import ssl

    import roslibpy_lite

    port = _free_port()
    argv, env = _unit_command(tmp_path, port)
    assert "--auth-file" in argv and "--certfile" in argv  # safe as shipped
    assert env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    proc = subprocess.Popen(argv, cwd=tmp_path, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    try:
        assert proc.stdout is not None
        lines = []
        for line in proc.stdout:
            lines.append(line)
            if "listening on wss://" in line:
                break
        else:
            pytest.fail("the unit's command exited:\n" + "".join(lines))

        async def call() -> object:
            ctx = ssl.create_default_context(cafile=str(tmp_path / "ca.pem"))
            async with roslibpy_lite.connect(f"wss://127.0.0.1:{port}", ssl=ctx,
                                             token=(tmp_path / "token").read_text()) as ros:
                return await ros.call_service("/rosapi/get_ros_version",
                                              "rosapi_msgs/srv/GetROSVersion", {})

        assert asyncio.run(call())["version"] == 2  # type: ignore[index]
        assert any((tmp_path / "log" / "roslibpy-lite-bridge").rglob("*")), "no ROS log files"
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(15)
        if proc.stdout is not None:
            proc.stdout.close()
    (tmp_path / "bare").mkdir()
    argv, env = _unit_command(tmp_path / "bare", _free_port(), with_log_dirs=False)
    failed = subprocess.run(argv, cwd=tmp_path, env=env, capture_output=True, text=True,
                            timeout=60)
    assert failed.returncode != 0
    assert "Failed to create log directory" in failed.stdout + failed.stderr
