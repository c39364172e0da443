"""A robot the relay does not admit says so, on its own side, within 5 s (issue 50, item 1).

A relay (the router) with mutual TLS letting in robot1 and robot2 by their certificates,
and a robot's bridge (``--no-websocket``) dialing it with a certificate that does not fit:
another robot's, one the relay does not name, or none. The robot logs an ERROR with the
reason and the flag or certificate to fix within 5 s of dialing, and never that it "is on
Zenoh". A robot given a tls/ endpoint without ``--zenoh-tls-ca`` does not start, as a relay
does not.
"""

from __future__ import annotations

import datetime
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import free_port, ros_env
from tests.relay.procs import Proc

trustme = pytest.importorskip("trustme")

pytestmark = pytest.mark.timeout(90)

READY = re.compile(r"relay listening on ws://127\.0\.0\.1:(\d+)")
SAID_WITHIN = 5.0
"""Seconds from dialing to the robot's ERROR (the issue's bound)."""


def _issue(ca: Any, tmp: Path, name: str) -> list[str]:
    """``--zenoh-tls-cert`` and ``--zenoh-tls-key`` of a certificate for ``name``."""
    issued = ca.issue_cert(name, common_name=name)
    cert, key = tmp / f"{name}.pem", tmp / f"{name}.key"
    issued.cert_chain_pems[0].write_to_path(cert)
    issued.private_key_pem.write_to_path(key)
    return ["--zenoh-tls-cert", str(cert), "--zenoh-tls-key", str(key)]


@pytest.fixture
def relay(tmp_path: Path) -> Iterator[tuple[str, Any]]:
    """A relay with mutual TLS naming robot1 and robot2; its endpoint and CA."""
    ca = trustme.CA()
    ca.cert_pem.write_to_path(tmp_path / "ca.pem")
    router = ca.issue_cert("127.0.0.1", common_name="router")
    router.cert_chain_pems[0].write_to_path(tmp_path / "router.pem")
    router.private_key_pem.write_to_path(tmp_path / "router.key")
    endpoint = f"tls/127.0.0.1:{free_port()}"
    proc = Proc([sys.executable, "-m", "bridge_server.zenoh.relay", "--port", "0",
                 "--zenoh-listen", endpoint, "--zenoh-tls-ca", str(tmp_path / "ca.pem"),
                 "--zenoh-tls-cert", str(tmp_path / "router.pem"), "--zenoh-tls-key",
                 str(tmp_path / "router.key"), "--zenoh-mtls", "--zenoh-robot", "robot1",
                 "--zenoh-robot", "robot2"], ros_env())
    try:
        proc.wait_for(READY)
        yield endpoint, ca
    finally:
        proc.stop()


def _at(line: str) -> datetime.datetime:
    return datetime.datetime.strptime(line[:23], "%Y-%m-%d %H:%M:%S,%f")


@pytest.mark.parametrize(("robot", "certificate", "said"), [
    ("robot1", "robot2", r"its certificate \(--zenoh-tls-cert \S+robot2\.pem\) is for "
     r"'robot2'.*give robot robot1's certificate.*or run this robot as --robot robot2"),
    ("robot3", "robot3", r"the relay must name it with --zenoh-robot robot3"),
    ("robot1", None, r"it gives no certificate.*give --zenoh-tls-cert and --zenoh-tls-key"),
])
def test_a_robot_the_relay_does_not_admit_says_why_within_5_s(
        relay: tuple[str, Any], tmp_path: Path, robot: str, certificate: str | None,
        said: str) -> None:
    """Another robot's certificate, a robot the relay does not name, no certificate: the
    robot logs an ERROR naming the reason and what to fix within 5 s of dialing, and never
    that it is on Zenoh."""
    endpoint, ca = relay
    tls = _issue(ca, tmp_path, certificate) if certificate else []
    proc = Proc([sys.executable, "-m", "bridge_server", "--no-websocket", "--robot", robot,
                 "--zenoh-connect", endpoint, "--zenoh-tls-ca", str(tmp_path / "ca.pem"),
                 *tls], ros_env())
    try:
        dialing = proc.wait_for(re.compile(r"^(\S+ \S+) INFO .*dialing out to Zenoh"))
        error = proc.wait_for(re.compile(r"^(\S+ \S+) ERROR .*" + said), SAID_WITHIN + 10)
        waited = (_at(error.group(1)) - _at(dialing.group(1))).total_seconds()
        assert waited < SAID_WITHIN, (waited, error.group(0))
        assert f"robot {robot}" in error.group(0)
        assert not any("is on Zenoh" in line for line in proc.lines), proc.lines
    finally:
        proc.stop()


def test_a_robot_with_a_tls_endpoint_and_no_ca_does_not_start() -> None:
    """``--zenoh-connect tls/...`` without ``--zenoh-tls-ca``: the robot's bridge exits with
    status 2 naming the flag, as a relay does (it ran on with no uplink before)."""
    done = subprocess.run([sys.executable, "-m", "bridge_server", "--no-websocket", "--robot",
                           "robot1", "--zenoh-connect", "tls/127.0.0.1:7447"], env=ros_env(),
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2, done.stderr
    assert "--zenoh-connect endpoint needs --zenoh-tls-ca" in done.stderr, done.stderr
