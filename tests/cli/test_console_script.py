"""The installed ``roslibpy-lite`` console script as a real process: output, Ctrl+C, exit codes."""

from __future__ import annotations

import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

from roslibpy_lite.cli import EXIT_CONNECT
from tests.cli.conftest import closed_port
from tests.examples.support import Program
from tests.helpers import ROOT, BridgeProcess, ros_env, wait_until

CLI = str(Path(sys.executable).parent / "roslibpy-lite")


def run(*argv: str) -> subprocess.CompletedProcess[str]:
    """Run the console script to completion."""
    return subprocess.run([CLI, *argv], cwd=ROOT, env=ros_env(), capture_output=True, text=True,
                          timeout=60)


def test_service_call_from_the_shell(bridge: BridgeProcess, multiplier: str) -> None:
    """The README's command: service call with YAML values prints 'result: 10.0'."""
    done = run("service", "call", multiplier, "mult_msgs/srv/MultFloats", "{x: 2.5, y: 4.0}",
               "--url", bridge.url, "--wait", "10")
    assert (done.returncode, done.stdout, done.stderr) == (0, "result: 10.0\n", "")


def test_no_bridge_from_the_shell() -> None:
    """No bridge: exit status 3 and exactly one line on stderr, no traceback."""
    url = f"ws://127.0.0.1:{closed_port()}"
    done = run("topic", "list", "--url", url)
    assert done.returncode == EXIT_CONNECT and done.stdout == ""
    assert len(done.stderr.splitlines()) == 1 and f"cannot connect to {url}" in done.stderr


def test_echo_stops_cleanly_on_ctrl_c(bridge: BridgeProcess, ros_node: Any, topic: str) -> None:
    """echo runs until Ctrl+C, then exits 0 without a traceback."""
    from std_msgs.msg import String

    pub = ros_node.create_publisher(String, topic, 10)
    timer = ros_node.create_timer(0.05, lambda: pub.publish(String(data="tick")))
    echo = Program([CLI, "topic", "echo", topic, "std_msgs/msg/String", "--url", bridge.url])
    try:
        echo.wait_for(r"^data: 'tick'$")
        echo.wait_for(r"^---$")
    finally:
        code = echo.interrupt()
        ros_node.destroy_timer(timer)
    assert code == 0, echo.dump()
    assert echo.err == [], echo.dump()


def test_pub_at_a_rate_until_ctrl_c(bridge: BridgeProcess, ros_node: Any, topic: str) -> None:
    """pub without --once/--times keeps publishing at --rate until Ctrl+C, then exits 0."""
    from std_msgs.msg import String

    got: list[str] = []
    lock = threading.Lock()

    def on_msg(msg: Any) -> None:
        with lock:
            got.append(msg.data)

    ros_node.create_subscription(String, topic, on_msg, 10)
    pub = Program([CLI, "topic", "pub", topic, "std_msgs/msg/String", "{data: beat}",
                   "--rate", "20", "--url", bridge.url])
    try:
        pub.wait_for(r"^publishing #3: \{\"data\": \"beat\"\}$")
        wait_until(lambda: len(got) >= 2, timeout=15, what="two messages at the subscriber")
    finally:
        code = pub.interrupt()
    assert code == 0, pub.dump()
    assert pub.err == [], pub.dump()
    assert set(got) == {"beat"}


def test_hz_reports_until_ctrl_c(bridge: BridgeProcess, ros_node: Any, topic: str) -> None:
    """hz prints a report every second and stops on Ctrl+C with status 0."""
    from std_msgs.msg import String

    pub = ros_node.create_publisher(String, topic, 10)
    timer = ros_node.create_timer(0.05, lambda: pub.publish(String(data="x")))
    hz = Program([CLI, "topic", "hz", topic, "std_msgs/msg/String", "--url", bridge.url])
    try:
        hz.wait_for(r"^average rate: \d+\.\d{3}$")
        hz.wait_for(r"^\tmin: .* window: \d+$")
    finally:
        code = hz.interrupt()
        ros_node.destroy_timer(timer)
    assert code == 0, hz.dump()
    assert hz.err == [], hz.dump()


def test_module_entry_point_and_no_ros_import() -> None:
    """``python -m roslibpy_lite.cli`` works, and importing the CLI loads no rclpy."""
    done = subprocess.run(
        [sys.executable, "-c",
         "import sys, roslibpy_lite.cli; assert 'rclpy' not in sys.modules, 'rclpy imported'"],
        cwd=ROOT, env=ros_env(), capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    shown = subprocess.run([sys.executable, "-m", "roslibpy_lite.cli", "interface", "show",
                            "std_msgs/msg/String"], cwd=ROOT, env=ros_env(), capture_output=True,
                           text=True, timeout=60)
    assert (shown.returncode, shown.stdout.splitlines()[-1]) == (0, "string data"), shown.stderr
