"""scripts/demo.sh as a user runs it: comes up, answers the CLI, and stops everything on Ctrl+C."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.examples.support import Program
from tests.helpers import ROOT, ros_env, wait_until

CLI = str(Path(sys.executable).parent / "roslibpy-lite")
# The demo sources scripts/setup.sh, which installs packages when pyproject.toml changed.
pytestmark = pytest.mark.timeout(400)


def group_gone(pgid: int) -> bool:
    """True when no process of the group is left."""
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return True
    return False


def demo_env(**extra: str) -> dict[str, str]:
    """The demo's environment: a ROS domain of its own (this run's plus 100), so nothing the
    demo's bridge and IMU leave in the ROS graph as they stop (a participant announced gone
    only when its lease ends) reaches the next tests' session bridge."""
    domain = (int(os.environ.get("ROS_DOMAIN_ID", "0")) + 100) % 200 + 1
    return ros_env(ROS_DOMAIN_ID=str(domain), **extra)


@pytest.fixture
def demo() -> Iterator[Program]:
    """The demo on a free port, in its own process group; killed after the test if still there."""
    program = Program(["bash", "scripts/demo.sh"], env=demo_env(PORT="0"), group=True)
    yield program
    program.kill()


def stock_roslibpy_snippet(demo: Program) -> str:
    """The stock-roslibpy lines the demo prints, as a Python program."""
    demo.wait_for(r"^\[demo\] Press Ctrl\+C")
    start = demo.out.index("[demo] or connect with stock roslibpy (pip install roslibpy):")
    end = demo.out.index("[demo] Press Ctrl+C to stop everything.")
    return "\n".join(line.removeprefix("[demo]   ") for line in demo.out[start + 1:end])


def python_action_snippet(demo: Program) -> str:
    """The Python lines the demo prints for sending /integrate_imu a goal."""
    demo.wait_for(r"^\[demo\] Press Ctrl\+C")
    start = demo.out.index("[demo] or from Python (.venv/bin/python):")
    end = demo.out.index("[demo] or connect with stock roslibpy (pip install roslibpy):")
    return "\n".join(line.removeprefix("[demo]   ") for line in demo.out[start + 1:end])


def cli(*args: str) -> subprocess.CompletedProcess[str]:
    """Run the installed console script."""
    return subprocess.run([CLI, *args], cwd=ROOT, capture_output=True, text=True, timeout=60,
                          env=ros_env())


def test_demo_serves_the_cli_and_stops_on_ctrl_c(demo: Program) -> None:
    """The demo comes up, the CLI and stock roslibpy call /mult_floats, Ctrl+C stops all."""
    url = demo.wait_for(r"^\[demo\] bridge on (ws://127\.0\.0\.1:\d+);", timeout=360)[1]
    hint = demo.wait_for(r"^\[demo\]   (\.venv/bin/roslibpy-lite service call .*)$")[1]
    assert hint == ('.venv/bin/roslibpy-lite service call /mult_floats mult_msgs/srv/MultFloats '
                    f'"{{x: 2.5, y: 4.0}}" --url {url}')
    demo.wait_for(r"^robot_app \| \[service\] serving /mult_floats")

    # --wait: on a loaded CI machine the graph may list the service later than 2 s.
    called = cli("service", "call", "/mult_floats", "mult_msgs/srv/MultFloats",
                 "{x: 2.5, y: 4.0}", "--url", url, "--wait", "15")
    assert (called.returncode, called.stdout, called.stderr) == (0, "result: 10.0\n", "")

    echoed = cli("topic", "echo", "/example_counter", "--count", "1", "--json", "--url", url)
    assert echoed.returncode == 0, echoed.stderr
    assert isinstance(json.loads(echoed.stdout)["data"], int)

    snippet = stock_roslibpy_snippet(demo)
    stock = subprocess.run([sys.executable, "-c", snippet], cwd=ROOT, capture_output=True,
                           text=True, timeout=60, env=ros_env())
    assert (stock.returncode, stock.stdout) == (0, "{'result': 10.0}\n"), (snippet, stock)

    hint = demo.wait_for(r"^\[demo\]   (\.venv/bin/roslibpy-lite action send_goal .*)$")[1]
    assert hint == (".venv/bin/roslibpy-lite action send_goal /integrate_imu "
                    f'mult_msgs/action/IntegrateImu "{{seconds: 2.0}}" --feedback --url {url}')
    sent = cli("action", "send_goal", "/integrate_imu", "mult_msgs/action/IntegrateImu",
               "{seconds: 0.5}", "--feedback", "--url", url, "--wait", "15")
    assert sent.returncode == 0, sent.stdout + sent.stderr
    assert "Feedback:" in sent.stdout
    assert sent.stdout.rstrip().endswith("Goal finished with status: SUCCEEDED"), sent.stdout
    snippet = python_action_snippet(demo)
    goal = subprocess.run([sys.executable, "-c", snippet], cwd=ROOT, capture_output=True,
                          text=True, timeout=60, env=ros_env())
    assert goal.returncode == 0 and "samples" in goal.stdout, (snippet, goal)
    demo.wait_for(r"^robot_app \| \[action\] /integrate_imu: done: total=")

    demo.wait_for(r"^robot_app \| \[imu\] #\d+ angular_velocity\.x=\S+ sum=\S+$")
    demo.wait_for(r"^robot_app \| \[service\] /mult_floats: 2\.5 \* 4\.0 = 10\.0$")

    assert demo.interrupt(timeout=60) == 0, demo.dump()  # Ctrl+C: SIGINT to the whole group
    assert demo.out[-1] == "[demo] demo stopped", demo.dump()
    for pattern in (r"^robot_app \| \[app\] stopped$", r"^imu_sim   \| \[imu_sim\] stopped after",
                    r"^bridge    \| .*shutting down"):
        demo.wait_for(pattern, timeout=1)
    assert not any("Traceback" in line for line in demo.out + demo.err), demo.dump()
    wait_until(lambda: group_gone(demo.proc.pid), timeout=10, what="every demo process to exit")


def test_demo_stops_everything_when_only_the_script_is_signalled(demo: Program) -> None:
    """SIGINT to the script alone (not its group) still stops the bridge, IMU and program."""
    demo.wait_for(r"^\[demo\] bridge on ws://", timeout=360)
    demo.wait_for(r"^robot_app \| \[service\] serving /mult_floats")
    demo.proc.send_signal(signal.SIGINT)
    assert demo.proc.wait(60) == 0, demo.dump()
    wait_until(lambda: group_gone(demo.proc.pid), timeout=10, what="every demo process to exit")
    demo.kill()  # joins the output readers
    assert demo.out[-1] == "[demo] demo stopped", demo.dump()
    demo.wait_for(r"^robot_app \| \[app\] stopped$", timeout=1)


def test_demo_reports_a_busy_port() -> None:
    """With the port taken, the demo says the bridge did not start and exits 1, leaving nothing."""
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        demo = Program(["bash", "scripts/demo.sh"], env=demo_env(PORT=str(port)), group=True)
        try:
            code = demo.proc.wait(360)
            wait_until(lambda: group_gone(demo.proc.pid), timeout=10, what="the demo to clean up")
        finally:
            demo.kill()
    assert code == 1, demo.dump()
    assert demo.out[-1] == f"[demo] the bridge did not start (is port {port} already in use?)"


def test_demo_runs_secured(tmp_path: Path) -> None:
    """`demo.sh -- <bridge flags>` serves wss with tokens: the sample program connects with
    $ROSLIBPY_LITE_TOKEN/$ROSLIBPY_LITE_CAFILE and the CLI calls its service."""
    import trustme

    from rosbridge_core.security.auth import add_principal

    ca = trustme.CA()
    ca.issue_cert("127.0.0.1").private_key_and_cert_chain_pem.write_to_path(
        str(tmp_path / "server.pem"))
    ca.cert_pem.write_to_path(str(tmp_path / "ca.pem"))
    auth = tmp_path / "auth.toml"
    app_token = add_principal(auth, "robot_app", "admin")
    cli_token = add_principal(auth, "laptop", "admin")
    env = demo_env(PORT="0", ROSLIBPY_LITE_TOKEN=app_token,
                  ROSLIBPY_LITE_CAFILE=str(tmp_path / "ca.pem"))
    demo = Program(["bash", "scripts/demo.sh", "--", "--certfile", str(tmp_path / "server.pem"),
                    "--auth-file", str(auth)], env=env, group=True)
    try:
        url = demo.wait_for(r"^\[demo\] bridge on (wss://127\.0\.0\.1:\d+);", timeout=360)[1]
        demo.wait_for(r"^robot_app \| \[service\] serving /mult_floats", timeout=60)
        called = cli("service", "call", "/mult_floats", "mult_msgs/srv/MultFloats",
                     "{x: 2.5, y: 4.0}", "--url", url, "--wait", "15", "--token", cli_token,
                     "--cafile", str(tmp_path / "ca.pem"))
        assert (called.returncode, called.stdout) == (0, "result: 10.0\n"), called.stderr
        assert demo.interrupt(timeout=60) == 0, demo.dump()
        # The script exits before its children are done: wait for them, or the kill below
        # would end the bridge mid-shutdown, and its DDS participant, with the action the
        # sample program served, would stay in the next tests' ROS graph for its lease.
        wait_until(lambda: group_gone(demo.proc.pid), timeout=10, what="every demo process to exit")
        assert not any(app_token in line or cli_token in line for line in demo.out + demo.err)
    finally:
        demo.kill()
