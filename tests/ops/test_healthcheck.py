"""`roslibpy-lite-bridge healthcheck`: given the bridge's options, or reading them from the one
running bridge's command line (the container's case is in test_deploy.py)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from bridge_server.healthcheck import HealthcheckError, bridge_argv
from tests.helpers import ROOT, BridgeProcess, ros_env
from tests.security.support import make_certs


def _check(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "bridge_server", "healthcheck", *args],
                          cwd=ROOT, env=ros_env(), capture_output=True, text=True, timeout=60)


def test_healthcheck_with_the_bridges_options(tmp_path: Path) -> None:
    """With the bridge's own options it passes over https trusting the served certificate,
    and fails in one line for the wrong scheme, a certificate it does not trust, or a
    stopped bridge."""
    certs = make_certs(tmp_path)
    bridge = BridgeProcess(args=["--certfile", str(certs.server)]).start()
    try:
        port = str(bridge.port)
        assert _check("--port", port, "--certfile", str(certs.server)).returncode == 0
        assert _check("--port", port, "--certfile", str(certs.server), "--cafile",
                      str(certs.ca)).returncode == 0
        plain = _check("--port", port)
        assert plain.returncode == 1 and plain.stderr.startswith(
            f"healthcheck: not ready: http://127.0.0.1:{port}/readyz: ")
        other = _check("--port", port, "--certfile", str(certs.server), "--cafile",
                       str(certs.other_ca))
        assert other.returncode == 1 and "CERTIFICATE_VERIFY_FAILED" in other.stderr
    finally:
        bridge.stop()
    gone = _check("--port", port, "--certfile", str(certs.server))
    assert gone.returncode == 1 and "https://127.0.0.1:" in gone.stderr
    assert len(gone.stderr.splitlines()) == 1


def _proc(tmp: Path, *cmdlines: list[str]) -> Path:
    for pid, argv in enumerate(cmdlines, start=10):
        (tmp / str(pid)).mkdir(parents=True)
        (tmp / str(pid) / "cmdline").write_bytes(b"".join(a.encode() + b"\0" for a in argv))
    (tmp / "self").mkdir()
    return tmp


def test_healthcheck_finds_the_bridge_among_its_workers_and_helpers(tmp_path: Path) -> None:
    """Of a supervisor, its workers, other helper commands and unrelated processes, the
    supervisor's options are the bridge's; none or two bridges is an error saying what to do."""
    bridge = ["/venv/bin/python", "/venv/bin/roslibpy-lite-bridge", "--port", "9443",
              "--certfile", "/etc/roslibpy-lite/server.pem", "--workers", "2"]
    proc = _proc(tmp_path / "a", bridge,
                 ["/venv/bin/python", "-m", "bridge_server", "--port", "9443",
                  "--worker-index", "0", "--worker-dir", "/tmp/w"],
                 ["/venv/bin/python", "/venv/bin/roslibpy-lite-bridge", "healthcheck"],
                 ["/venv/bin/python", "/venv/bin/roslibpy-lite-bridge", "add-principal", "x"],
                 ["/usr/bin/sleep", "100"])
    assert bridge_argv(proc) == bridge[2:]
    with pytest.raises(HealthcheckError, match="no running roslibpy-lite-bridge found"):
        bridge_argv(_proc(tmp_path / "b", ["/usr/bin/sleep", "100"]))
    with pytest.raises(HealthcheckError, match="2 roslibpy-lite-bridge processes"):
        bridge_argv(_proc(tmp_path / "c", bridge, ["python", "-m", "bridge_server"]))
