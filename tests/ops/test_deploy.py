"""deploy/: the systemd unit passes systemd-analyze, the Dockerfile runs the real entry point."""

from __future__ import annotations

import contextlib
import json
import re
import shutil
import signal
import socket
import subprocess
import sys
import tomllib
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.helpers import ROOT, free_port, ros_env

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
    """FROM first, sources copied exist, a non-root user, DDS on this machine, a health check
    that is the bridge's own, and ENTRYPOINT + CMD that parse with the bridge's argument
    parser and pass its exposure rule: every address, but with tokens and TLS, whose files
    come from the mounted /etc/roslibpy-lite/ the header documents."""
    from bridge_server.__main__ import parse_args
    from rosbridge_core.security import exposure_refusal

    text = DOCKERFILE.read_text()
    steps = _instructions(text)
    words = [w for w, _ in steps]
    assert words[0] == "FROM"
    assert [rest for w, rest in steps if w == "FROM"][-1].startswith("python:3.11")
    for word, rest in steps:
        if word == "COPY" and not rest.startswith("--from="):
            for src in rest.split()[:-1]:
                assert (ROOT / src).exists(), f"COPY {src}: no such path in the repository"
    users = [rest for w, rest in steps if w == "USER"]
    assert users and users[-1] not in ("root", "0")
    env = " ".join(rest for w, rest in steps if w == "ENV")
    assert "ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST" in env
    assert "ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET" in text  # the header says how to widen it
    health = next(rest for w, rest in steps if w == "HEALTHCHECK")
    assert json.loads(health.partition("CMD")[2]) == ["roslibpy-lite-bridge", "healthcheck"]
    entry = json.loads(next(rest for w, rest in steps if w == "ENTRYPOINT"))
    cmd = json.loads(next(rest for w, rest in steps if w == "CMD"))
    assert entry == ["roslibpy-lite-bridge"]
    flags = {a for a in cmd if a.startswith("--")}
    assert flags <= _bridge_flags(), flags - _bridge_flags()
    args = parse_args(cmd)
    assert (args.host, args.port, args.workers) == ("0.0.0.0", 9090, 2)
    assert exposure_refusal(args) is None and not args.insecure
    files = [args.auth_file, args.certfile, args.keyfile]
    for path in files:
        assert path.startswith("/etc/roslibpy-lite/"), path
        assert f"{Path(path).name} " in text.partition("FROM")[0], f"{path} not in the header"
    assert "-v /etc/roslibpy-lite:/etc/roslibpy-lite:ro" in text
    assert "EXPOSE" in words and ("EXPOSE", "9090") in steps
    # The robot's interfaces: a stage --build-context replaces, built with the one script.
    assert ("FROM", "scratch AS interfaces") in steps
    assert any(w == "COPY" and rest.startswith("--from=interfaces ") for w, rest in steps)
    assert any(w == "RUN" and "scripts/build-interfaces.sh msgs/interfaces interfaces" in rest
               and '".[bridge,build-interfaces]"' in rest for w, rest in steps)


def _container_run(tmp: Path, argv: list[str], health: list[str]) -> dict[str, object]:
    """Run ``argv`` (a bridge) as a container's main process would, alone in a PID namespace
    of its own with its own /proc, wait for its ready line, run ``health`` (the health check)
    while it serves and again after it stopped; returns the bridge's lines and both results."""
    driver = tmp / "container.py"
    driver.write_text(CONTAINER_DRIVER)
    out = subprocess.run(["unshare", "--pid", "--fork", "--mount-proc", sys.executable,
                          str(driver), json.dumps(argv), json.dumps(health)],
                         cwd=tmp, env=ros_env(PYTHONPATH=str(ROOT)),  # this checkout's code
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    return json.loads(out.stdout.splitlines()[-1])  # type: ignore[no-any-return]


CONTAINER_DRIVER = """
import json, signal, subprocess, sys
argv, health = json.loads(sys.argv[1]), json.loads(sys.argv[2])
bridge = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
lines = []
for line in bridge.stdout:
    lines.append(line)
    if "bridge_server listening on" in line:
        break
def check():
    done = subprocess.run(health, capture_output=True, text=True, timeout=30)
    return [done.returncode, done.stderr]
serving = check() if bridge.poll() is None else None
bridge.send_signal(signal.SIGTERM)
lines += bridge.stdout.readlines()
bridge.wait(30)
print(json.dumps({"lines": lines, "serving": serving, "stopped": check()}))
"""


def _docker_files(tmp: Path) -> dict[str, str]:
    """What an operator mounts at /etc/roslibpy-lite/: a token file and a certificate."""
    import trustme

    from rosbridge_core.security.auth import add_principal

    add_principal(tmp / "auth.toml", "dashboard", "viewer")
    cert = trustme.CA().issue_cert("127.0.0.1")
    cert.cert_chain_pems[0].write_to_path(str(tmp / "server.pem"))
    cert.private_key_pem.write_to_path(str(tmp / "server.key"))
    return {f"/etc/roslibpy-lite/{name}": str(tmp / name)
            for name in ("auth.toml", "server.pem", "server.key")}


@pytest.mark.skipif(shutil.which("unshare") is None, reason="unshare (util-linux) missing")
def test_dockerfile_healthcheck_follows_the_port_and_scheme(tmp_path: Path) -> None:
    """The image's ENTRYPOINT + CMD with another port, as `docker run IMAGE ... --port P`
    gives them, serve wss:// (2 workers); the HEALTHCHECK command, run beside them as in the
    container, passes while the bridge serves and fails once it stopped."""
    steps = _instructions(DOCKERFILE.read_text())
    entry = json.loads(next(rest for w, rest in steps if w == "ENTRYPOINT"))
    cmd = json.loads(next(rest for w, rest in steps if w == "CMD"))
    health = json.loads(next(rest for w, rest in steps if w == "HEALTHCHECK").partition("CMD")[2])
    bin_dir = Path(sys.executable).parent
    files = _docker_files(tmp_path)
    argv = [str(bin_dir / entry[0]), *[files.get(a, a) for a in cmd], "--port", str(free_port())]
    result = _container_run(tmp_path, argv, [str(bin_dir / health[0]), *health[1:]])
    assert any("listening on wss://0.0.0.0:" in line for line in result["lines"]), result  # type: ignore[attr-defined]
    assert result["serving"] == [0, ""], result
    assert result["stopped"] == [1, "healthcheck: no running roslibpy-lite-bridge found; give "
                                 "the bridge's options: roslibpy-lite-bridge healthcheck "
                                 "--port PORT ...\n"], result


def test_dockerfile_without_its_mounted_files_names_the_first_missing_one() -> None:
    """The image's command without /etc/roslibpy-lite/ mounted stops with one line naming the
    file and the user, not a traceback."""
    steps = _instructions(DOCKERFILE.read_text())
    cmd = json.loads(next(rest for w, rest in steps if w == "CMD"))
    out = subprocess.run([sys.executable, "-m", "bridge_server", *cmd], cwd=ROOT, env=ros_env(),
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 1
    assert "cannot start: --certfile: cannot read /etc/roslibpy-lite/server.pem as user" \
        in out.stderr
    assert "Traceback" not in out.stderr


def _unit_command(tmp: Path, port: int, with_log_dirs: bool = True) -> tuple[list[str], dict[str, str]]:
    """The unit's exact ExecStart and Environment, with its files pointed at ``tmp``: the venv
    of this checkout, an auth file and a certificate made here, a free port, this run's
    ROS domain, the directories systemd would make for LogsDirectory/StateDirectory, and the
    HOME a system user without a home directory has under ProtectHome (nothing writable)."""
    import trustme

    from rosbridge_core.security.auth import add_principal

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


@contextlib.contextmanager
def _serving(argv: list[str], env: dict[str, str], cwd: Path) -> Iterator[subprocess.Popen[str]]:
    """``argv`` (the unit's command) running, once it printed its ready line (every worker
    listens); stopped with SIGTERM afterwards."""
    proc = subprocess.Popen(argv, cwd=cwd, env=env, stdout=subprocess.PIPE,
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
        yield proc
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(15)
        if proc.stdout is not None:
            proc.stdout.close()


def test_unit_allows_the_address_families_its_command_uses(tmp_path: Path) -> None:
    """The unit's exact ExecStart serving (with --workers: the workers' own sockets are unix
    sockets): every address family its processes hold sockets of, AF_UNIX among them, is in
    RestrictAddressFamilies, which systemd would refuse them otherwise."""
    import psutil

    service = _unit_sections(UNIT.read_text())["Service"]
    allowed = set(" ".join(service["RestrictAddressFamilies"]).split())
    argv, env = _unit_command(tmp_path, free_port())
    with _serving(argv, env, tmp_path) as proc:
        top = psutil.Process(proc.pid)
        held = [c for p in [top, *top.children(recursive=True)]
                for c in p.net_connections(kind="all")]
    used = {socket.AddressFamily(c.family).name for c in held}
    assert used <= allowed, f"the bridge uses {sorted(used - allowed)}, the unit refuses them"
    if "--workers" in argv:
        workers = [c.laddr for c in held if c.family == socket.AF_UNIX
                   and re.search(r"/(worker|forward)-\d+\.sock$", str(c.laddr))]
        assert workers, f"no worker's unix socket among {sorted(map(str, held))}"


def test_unit_command_serves_as_a_user_without_a_home(tmp_path: Path) -> None:
    """The unit's exact ExecStart, with its Environment and log directories, starts the bridge
    when HOME is not writable (a system user without a home), serves wss with a token, and
    ROS writes its logs to LogsDirectory; without those directories rclpy dies as reported."""
    import asyncio
    import ssl

    import roslibpy_lite

    port = free_port()
    argv, env = _unit_command(tmp_path, port)
    assert "--auth-file" in argv and "--certfile" in argv  # safe as shipped
    assert env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    with _serving(argv, env, tmp_path):

        async def call() -> object:
            ctx = ssl.create_default_context(cafile=str(tmp_path / "ca.pem"))
            async with roslibpy_lite.connect(f"wss://127.0.0.1:{port}", ssl=ctx,
                                             token=(tmp_path / "token").read_text()) as ros:
                return await ros.call_service("/rosapi/get_ros_version",
                                              "rosapi_msgs/srv/GetROSVersion", {})

        assert asyncio.run(call())["version"] == 2  # type: ignore[index]
        assert any((tmp_path / "log" / "roslibpy-lite-bridge").rglob("*")), "no ROS log files"
    (tmp_path / "bare").mkdir()
    argv, env = _unit_command(tmp_path / "bare", free_port(), with_log_dirs=False)
    failed = subprocess.run(argv, cwd=tmp_path, env=env, capture_output=True, text=True,
                            timeout=60)
    assert failed.returncode != 0
    assert "Failed to create log directory" in failed.stdout + failed.stderr


STEPS_SKIPPED = {
    "useradd": "makes a system user on the test machine (the steps use nobody instead)",
    "python3.11 -m venv": "the test runs in this checkout's venv",
    "/opt/roslibpy-lite/.venv/bin/pip install": "tests/install builds and installs the wheel",
    "cp deploy/roslibpy-lite-bridge.service": "installs into the machine's systemd",
    "systemctl": "needs systemd running (systemd-analyze verify checks the unit)",
}


def _install_steps() -> list[str]:
    """The commands of the unit's header, in order (the lines starting with `#   $ `)."""
    return [line.partition("$ ")[2] for line in UNIT.read_text().splitlines()
            if line.startswith("#   $ ")]


@pytest.mark.skipif(shutil.which("unshare") is None or shutil.which("openssl") is None,
                    reason="unshare or openssl missing")
def test_unit_install_steps_run_as_written(tmp_path: Path) -> None:
    """The unit header's install steps, run as written in a temporary root (/etc and /opt
    moved there, the service user played by nobody): the auth file and its folder are made
    readable by that user only, the certificate is made, the robot's interfaces build, and
    the unit's ExecStart then serves wss:// with the printed token, which the health check
    step confirms. Only the steps that change the machine itself are left out (see
    STEPS_SKIPPED); the unit passes systemd-analyze in its own test."""
    import asyncio
    import pwd
    import ssl
    import stat

    import roslibpy_lite

    steps = _install_steps()
    skipped = [s for s in steps if any(s.startswith(k) for k in STEPS_SKIPPED)]
    assert len(skipped) == len(STEPS_SKIPPED) + 1  # systemctl twice
    etc = tmp_path / "etc" / "roslibpy-lite"
    venv = Path(sys.prefix)

    def here(command: str) -> str:
        return (command.replace("/etc/roslibpy-lite", str(etc))
                .replace("/opt/roslibpy-lite/.venv", str(venv))
                .replace("roslibpy-bridge ", "nobody "))

    run = [here(s) for s in steps if s not in skipped]
    assert not etc.parent.exists()
    out = subprocess.run(["bash", "-euo", "pipefail", "-c", "\n".join(run[:-1])], cwd=ROOT,
                         env=ros_env(VIRTUAL_ENV=str(venv), PYTHONPATH=str(ROOT)),
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stdout + out.stderr
    token = out.stdout.strip()
    nobody = pwd.getpwnam("nobody")
    auth = etc / "auth.toml"
    assert stat.S_IMODE(auth.stat().st_mode) == 0o600 and auth.stat().st_uid == nobody.pw_uid
    assert stat.S_IMODE(etc.stat().st_mode) == 0o750 and etc.stat().st_gid == nobody.pw_gid
    assert (etc / "server.key").stat().st_uid == nobody.pw_uid
    port = free_port()
    service = _unit_sections(UNIT.read_text())["Service"]
    argv = [here(a) for a in service["ExecStart"][0].split()]
    argv[argv.index("--port") + 1] = str(port)
    health = run[-1].split()
    assert health[1:] == ["healthcheck"]
    result = _container_run(tmp_path, argv, health)
    assert result["serving"] == [0, ""], result

    async def call() -> object:
        ctx = ssl.create_default_context(cafile=str(etc / "server.pem"))
        async with roslibpy_lite.connect(f"wss://127.0.0.1:{port}", ssl=ctx, token=token) as ros:
            return await ros.call_service("/rosapi/get_ros_version",
                                          "rosapi_msgs/srv/GetROSVersion", {})

    bridge = subprocess.Popen(argv, cwd=tmp_path, env=ros_env(PYTHONPATH=str(ROOT)),
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        assert bridge.stdout is not None
        for line in bridge.stdout:
            if "listening on wss://" in line:
                break
        assert asyncio.run(call())["version"] == 2  # type: ignore[index]
    finally:
        bridge.send_signal(signal.SIGTERM)
        bridge.wait(15)
        if bridge.stdout is not None:
            bridge.stdout.close()
