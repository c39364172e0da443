"""The README's code runs as written: each marked Python block, as a user would run it."""

from __future__ import annotations

import os
import re
import shlex
import threading
from pathlib import Path
from typing import Any

from robot_msgs.msg import Status as RosStatus
from std_msgs.msg import String

from tests.helpers import ROOT, BridgeProcess, marked_blocks, run_snippet

MARKED = marked_blocks(ROOT / "README.md", "readme-test")
BLOCKS = dict(reversed(MARKED))  # the first block of each kind
ACTIONS = next(code for kind, code in MARKED if kind == "bridge" and "send_goal" in code)


def test_readme_has_its_examples() -> None:
    """The README carries its tested examples: asyncio, MockRos, the blocking client,
    recording and a client of a relay."""
    assert set(BLOCKS) == {"bag", "bridge", "mock", "relay", "sync"}


def test_client_example_runs_against_the_bridge(bridge: BridgeProcess) -> None:
    """The client example serves and calls a service and gets a latched typed message."""
    out = run_snippet(BLOCKS["bridge"], bridge)
    assert "2.5 * 4.0 = 10.0" in out
    assert "got Int16(data=3)" in out


def test_mock_example_runs() -> None:
    """The MockRos example passes its own assertion."""
    assert "MockRos test passed" in run_snippet(BLOCKS["mock"])


def test_blocking_example_runs_against_the_bridge(bridge: BridgeProcess) -> None:
    """The blocking-client example serves, calls and hears a message without async/await."""
    out = run_snippet(BLOCKS["sync"], bridge)
    assert "6 * 7 = 42.0" in out
    assert "heard {'data': 'hello'}" in out


def test_actions_example_runs_against_the_bridge(bridge: BridgeProcess) -> None:
    """The actions example serves /readme_integrate_imu, sends it a goal, hears feedback and result."""
    out = run_snippet(ACTIONS, bridge)
    assert out.count("running sum:") == 5
    assert out.splitlines()[-1] == "SUCCEEDED 1.0 5"


def test_bag_example_records_reads_and_plays(bridge: BridgeProcess, ros_node: Any,
                                             tmp_path: Path) -> None:
    """The recording example, while rclpy publishes the robot's own Status: five typed
    messages in the file, read back, then played to the robot (tests/bag checks that rclpy
    gets what is played)."""
    pub = ros_node.create_publisher(RosStatus, "/robot/status", 10)
    stop = threading.Event()

    def publish() -> None:  # the robot, at 20 Hz, until the example is done
        n = 0
        while not stop.wait(0.05):
            pub.publish(RosStatus(label=f"robot {n}"))
            n += 1

    thread = threading.Thread(target=publish, daemon=True)
    thread.start()
    try:
        code = BLOCKS["bag"].replace('"run.mcap"', repr(str(tmp_path / "run.mcap")))
        out = run_snippet(code, bridge)
    finally:
        stop.set()
        thread.join()
    lines = out.splitlines()
    assert "5 msgs" in lines[0] and "0 dropped" in lines[0], out
    assert all(line.startswith("/robot/status Status robot ") for line in lines[1:6]), out
    assert lines[6] == "5 messages"


def _relay_commands() -> tuple[list[str], list[str], list[str]]:
    """The README's certificates, relay and robot commands (their words after the program),
    from its relay section (lines continued with a backslash joined)."""
    section = (ROOT / "README.md").read_text().split("### Robots behind NAT")[1]
    block = re.sub(r"\\\n\s*", " ", section.split("```bash")[1].split("```")[0])
    lines = [line.strip() for line in block.splitlines()]
    certs = next(line for line in lines if line.startswith("roslibpy-lite-relay certs "))
    relay = next(line for line in lines
                 if line.startswith("roslibpy-lite-relay ") and line != certs)
    robot = next(line for line in lines if line.startswith("roslibpy-lite-bridge "))
    return shlex.split(certs)[1:], shlex.split(relay)[1:], shlex.split(robot)[1:]


def test_relay_example_runs_through_a_relay(ros_node: Any, tmp_path: Path) -> None:
    """The README's three commands run as written (the relay's ports, host and files put on
    this machine): the fleet's certificates made, the robot's bridge, with no listener, dials
    out to the relay over mutual TLS, and the client example hears the robot's /chatter
    through the relay with a token."""
    import subprocess
    import sys

    from tests.helpers import free_port, ros_env, wait_until
    from tests.security.support import make_auth_file

    certs_args, relay_args, robot_args = _relay_commands()
    zport = free_port()
    auth = make_auth_file(tmp_path)
    swap = {"0.0.0.0": "127.0.0.1", "auth.toml": str(auth.path), "fleet": str(tmp_path / "fleet"),
            "relay.example.com": "127.0.0.1",
            "tls/0.0.0.0:7447": f"tls/127.0.0.1:{zport}",
            "tls/relay.example.com:7447": f"tls/127.0.0.1:{zport}"}

    def here(args: list[str]) -> list[str]:  # this machine's ports, host, files
        return [swap.get(a, str(tmp_path / a) if a.startswith("fleet/") else a) for a in args]

    made = subprocess.run([sys.executable, "-m", "bridge_server.zenoh.relay", *here(certs_args)],
                          cwd=ROOT, env=ros_env(), capture_output=True, text=True, timeout=60)
    assert made.returncode == 0, made.stderr
    relay_cmd = [sys.executable, "-m", "bridge_server.zenoh.relay", *here(relay_args),
                 "--port", "0"]
    robot_cmd = [sys.executable, "-m", "bridge_server", *here(robot_args)]
    logs = [tmp_path / "relay.log", tmp_path / "robot.log"]
    procs = []
    for cmd, log in zip((relay_cmd, robot_cmd), logs, strict=True):
        with log.open("w") as sink:  # a file, not a pipe nobody drains while the test runs
            procs.append(subprocess.Popen(cmd, cwd=ROOT, env=ros_env(), stdout=sink,
                                          stderr=subprocess.STDOUT))
    pub = ros_node.create_publisher(String, "/chatter", 10)
    stop = threading.Event()

    def publish() -> None:  # the robot's talker, at 20 Hz, until the example is done
        while not stop.wait(0.05):
            pub.publish(String(data="hello from behind NAT"))

    thread = threading.Thread(target=publish, daemon=True)
    thread.start()
    try:
        ready = wait_until(lambda: re.search(r"relay listening on ws://[\d.]+:(\d+)",
                                             logs[0].read_text()) or procs[0].poll(),
                           30, "the relay's ready line")
        assert isinstance(ready, re.Match), logs[0].read_text()
        port = int(ready[1])
        url = f"ws://127.0.0.1:{port}/robot1"
        wait_until(lambda: _robot_served(url, auth.tokens["admin"]), 30, "the robot at the relay")
        code = BLOCKS["relay"].replace("ws://relay.example.com:9090/robot1", url)
        os.environ["RELAY_TOKEN"] = auth.tokens["admin"]
        try:
            out = run_snippet(code)
        finally:
            del os.environ["RELAY_TOKEN"]
        assert out.strip() == "robot1 says hello from behind NAT", out
    finally:
        stop.set()
        thread.join()
        for proc in procs:
            proc.terminate()
        for proc in procs:
            proc.wait(20)


def _robot_served(url: str, token: str) -> bool:
    """Whether the relay admits a client of the robot (not 404: the robot is on Zenoh)."""
    from websockets.exceptions import InvalidStatus
    from websockets.sync.client import connect

    try:
        with connect(url, additional_headers={"Authorization": f"Bearer {token}"},
                     open_timeout=10):
            return True
    except InvalidStatus as exc:
        if exc.response.status_code != 404:
            raise
        return False
