"""The bridge and the relay exit with their own status every time: 1 for a start they refuse,
0 for a clean stop (SIGINT, SIGTERM), whatever rclpy's, Fast DDS's or Zenoh's threads are
doing as the process ends (issue 43: a refusal died of SIGABRT, exit 134, 1 run in 30)."""

from __future__ import annotations

import re
import signal
import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.helpers import ROOT, free_port, ros_env
from tests.relay.procs import Proc

ABORT = "terminate called without an active exception"
BATCH = 4
"""Starts run at once: the abort is a race with the process's own start-up threads, which
parallel starts on a loaded machine lose more often (issue 43's numbers were such runs)."""


@pytest.fixture
def taken_port() -> Iterator[int]:
    """A port something else listens on."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        sock.listen()
        yield sock.getsockname()[1]


@pytest.fixture
def not_a_certificate(tmp_path: Path) -> Path:
    """A --certfile that is no PEM certificate."""
    bad = tmp_path / "server.pem"
    bad.write_text("not a certificate\n")
    return bad


def _run_all(commands: list[list[str]]) -> list[subprocess.CompletedProcess[str]]:
    """Run the commands, BATCH at a time; each result with its stderr."""
    done: list[subprocess.CompletedProcess[str]] = []
    for first in range(0, len(commands), BATCH):
        procs = [(cmd, subprocess.Popen(cmd, cwd=ROOT, env=ros_env(), stdin=subprocess.DEVNULL,
                                        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                        text=True))
                 for cmd in commands[first:first + BATCH]]
        for cmd, proc in procs:
            _, err = proc.communicate(timeout=60)
            done.append(subprocess.CompletedProcess(cmd, proc.returncode, "", err))
    return done


def _statuses(results: list[subprocess.CompletedProcess[str]]) -> dict[int, int]:
    counts: dict[int, int] = {}
    for r in results:
        counts[r.returncode] = counts.get(r.returncode, 0) + 1
    return counts


def test_refused_starts_exit_1_every_time(taken_port: int, not_a_certificate: Path) -> None:
    """32 refused starts, half of them after ROS is up (the port is taken), all exit 1 with the
    refusal and no abort.

    Not 200: a start whose refusal comes after ROS started costs ~0.5 s of CPU (rclpy, a node,
    its executor thread), ~0.3 s one refused before; 32 of them keep the test within a minute
    on two busy cores. Issue 43's refusal came after ROS had started and aborted 16 times in
    200 parallel starts here (8 %); 16 such starts all pass by chance 26 % of the time, which
    is why test_the_status_survives_an_rclpy_thread_inside_cpp_at_exit shows the mechanism
    at every run. The certificate refusal now comes before ROS starts (so it cannot abort).
    """
    bridge = [sys.executable, "-m", "bridge_server"]
    commands = [[*bridge, "--port", str(taken_port)],
                [*bridge, "--port", "0", "--certfile", str(not_a_certificate)]] * 16
    results = _run_all(commands)
    assert _statuses(results) == {1: 32}, [r.stderr for r in results if r.returncode != 1][:3]
    for r in results:
        assert "cannot start: " in r.stderr and ABORT not in r.stderr, r.stderr


@pytest.mark.parametrize("program", ["bridge", "relay"])
def test_the_status_survives_an_rclpy_thread_inside_cpp_at_exit(
        program: str, not_a_certificate: Path) -> None:
    """With an rclpy thread in 1 ms waits as the process ends (tests/bridge/exit_probe.py),
    a refused start of the bridge and of the relay still exits 1, 4 times in 4."""
    refused = {"bridge": ["--port", "0", "--certfile", str(not_a_certificate)],
               "relay": ["--port", "0"]}[program]  # the relay: no Zenoh endpoint given
    probe = [sys.executable, "-m", "tests.bridge.exit_probe", program, *refused]
    results = _run_all([probe] * 4)
    assert _statuses(results) == {1: 4}, [r.stderr for r in results if r.returncode != 1][:2]
    assert all("cannot start: " in r.stderr for r in results), results[0].stderr


def _stop_cleanly(argv: list[str], ready: str, sig: int) -> tuple[int, str]:
    proc = Proc(argv, ros_env())
    try:
        proc.wait_for(re.compile(ready))
        proc.proc.send_signal(sig)
        status = proc.proc.wait(20)
    finally:
        proc.stop()
    return status, "\n".join(proc.lines)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_clean_stop_exits_0_every_time(sig: int) -> None:
    """A bridge stopped by SIGTERM or SIGINT exits 0, 3 times in 3, with an rclpy thread in
    1 ms waits as the process ends (its own node and executor thread closed first)."""
    probe = [sys.executable, "-m", "tests.bridge.exit_probe", "bridge", "--port", "0"]
    for _ in range(3):
        status, log = _stop_cleanly(probe, r"bridge_server listening on ws://", sig)
        assert status == 0, log
        assert "bridge_server shutting down" in log and ABORT not in log, log


def test_a_relay_stopped_cleanly_exits_0() -> None:
    """A relay (a Zenoh router) stopped by SIGTERM exits 0, twice in 2, with an rclpy thread in
    1 ms waits as the process ends (its Zenoh session closed first)."""
    for _ in range(2):
        probe = [sys.executable, "-m", "tests.bridge.exit_probe", "relay", "--port", "0",
                 "--zenoh-listen", f"tcp/127.0.0.1:{free_port()}"]
        status, log = _stop_cleanly(probe, r"relay listening on ws://", signal.SIGTERM)
        assert status == 0, log
        assert "relay shutting down" in log and ABORT not in log, log
