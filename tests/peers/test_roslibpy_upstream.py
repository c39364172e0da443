"""roslibpy's own upstream action tests (``tests/ros2/test_actions.py`` of its 2.1.0 sources,
unchanged) against our bridge, on both of its transports.

They expect a bridge at 127.0.0.1:9090 and an ``example_interfaces/action/Fibonacci``
server on ``/fibonacci``. That package is not on PyPI: ``tests/interfaces/example_interfaces``
builds it into the venv (scripts/setup.sh), and scripts/setup.sh fetches the sources.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import BridgeProcess

# scripts/setup.sh unpacks them into the venv running the tests (.venv, or .venv-kilted)
UPSTREAM = Path(sys.prefix) / "peer-src" / "roslibpy-2.1.0" / "tests"
STEP_S = 0.5  # per Fibonacci number: test_cancel cancels after 2 s, while order 10 runs on


def _port_free(port: int) -> bool:
    with socket.socket() as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


@pytest.fixture(scope="module")
def bridge_9090() -> Iterator[BridgeProcess]:
    """Our bridge on the port roslibpy's tests hard-code."""
    assert _port_free(9090), "roslibpy's upstream tests need 127.0.0.1:9090, which is taken"
    bridge = BridgeProcess(port=9090).start()
    yield bridge
    bridge.kill()


@pytest.fixture(scope="module")
def fibonacci(module_node: Any) -> Iterator[Any]:
    """An rclpy Fibonacci server on /fibonacci, STEP_S per number, honouring cancels."""
    from example_interfaces.action import Fibonacci
    from rclpy.action.server import ActionServer, CancelResponse
    from rclpy.callback_groups import ReentrantCallbackGroup

    def execute(goal: Any) -> Any:
        sequence = [0, 1]
        for i in range(1, goal.request.order):
            if goal.is_cancel_requested:
                goal.canceled()
                return Fibonacci.Result(sequence=sequence)
            sequence.append(sequence[i] + sequence[i - 1])
            goal.publish_feedback(Fibonacci.Feedback(sequence=sequence))
            time.sleep(STEP_S)
        goal.succeed()
        return Fibonacci.Result(sequence=sequence)

    server = ActionServer(module_node, Fibonacci, "/fibonacci", execute,  # type: ignore[no-untyped-call]
                          cancel_callback=lambda _goal: CancelResponse.ACCEPT,
                          callback_group=ReentrantCallbackGroup())
    yield server
    server.destroy()  # type: ignore[no-untyped-call]


@pytest.mark.parametrize("transport", ["twisted", "asyncio"])
def test_roslibpy_upstream_action_tests(bridge_9090: BridgeProcess, fibonacci: Any,
                                        transport: str) -> None:
    """roslibpy's test_fibonacci and test_cancel pass against our bridge, as written upstream."""
    assert UPSTREAM.is_dir(), f"{UPSTREAM} is missing: run scripts/setup.sh"
    env = {**os.environ, "ROSLIBPY_TRANSPORT": transport, "PYTHONDONTWRITEBYTECODE": "1"}
    proc = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--rootdir",
         str(UPSTREAM), "-c", os.devnull, "ros2/test_actions.py"],
        cwd=UPSTREAM, env=env, capture_output=True, text=True, timeout=120,
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-2000:]
    assert "2 passed" in proc.stdout, proc.stdout[-2000:]
