"""MCP answers an agent (and its operator) can act on, against real processes: a bad token
names the file it came from, and a robot not up at start is waited for and said so in the
log, not the end of the server."""

from __future__ import annotations

import subprocess
import time
from collections.abc import Callable
from pathlib import Path

from tests.helpers import ROOT, BridgeProcess, free_port, ros_env
from tests.mcp.http_support import attempt, start_args
from tests.security.support import AuthFile


def test_a_refused_token_names_the_token_file(auth_bridge: BridgeProcess, auth: AuthFile,
                                              tmp_path: Path) -> None:
    """A token from --token-file the bridge refuses ends the server with an error naming
    that file, not the --token / $ROSLIBPY_LITE_TOKEN it did not use; the token is not in it."""
    token_file = tmp_path / "agent.token"
    wrong = "x" * 43
    token_file.write_text(wrong + "\n")
    done = subprocess.run(
        start_args(auth_bridge.url, free_port(), "--no-http-auth", "--token-file",
                   str(token_file), "--start-wait", "30"),
        cwd=ROOT, env=ros_env(PYTHONPATH=str(ROOT)), capture_output=True, text=True, timeout=60)
    assert done.returncode == 3, done.stderr
    assert f"--token-file {token_file}" in done.stderr, done.stderr
    assert "$ROSLIBPY_LITE_TOKEN" not in done.stderr and wrong not in done.stderr


async def test_a_robot_not_up_at_start_is_waited_for(
    make_bridge: Callable[..., BridgeProcess], tmp_path: Path
) -> None:
    """With no bridge at its URL the server does not end: it logs that the robot is not
    reachable yet and tries again; once a bridge starts there, it serves MCP."""
    bridge_port, port = free_port(), free_port()
    log = tmp_path / "mcp.log"
    with log.open("wb") as err:
        proc = subprocess.Popen(
            start_args(f"ws://127.0.0.1:{bridge_port}", port, "--no-http-auth", "--timeout",
                       "1", "--start-wait", "90"),
            cwd=ROOT, env=ros_env(PYTHONPATH=str(ROOT)), stdin=subprocess.DEVNULL, stderr=err)
    try:
        deadline = time.monotonic() + 60
        while "not reachable yet" not in log.read_text():  # the log is the only sign
            assert proc.poll() is None, f"the server ended: {log.read_text()}"
            assert time.monotonic() < deadline, log.read_text()
            time.sleep(0.1)
        assert "--start-wait" in log.read_text()
        make_bridge(port=bridge_port)
        url = f"http://127.0.0.1:{port}/mcp"
        while (served := await attempt(url)).tools is None:
            assert proc.poll() is None, f"the server ended: {log.read_text()}"
            assert time.monotonic() < deadline + 60, (served, log.read_text())
            time.sleep(0.2)
        assert "list_topics" in served.tools
    finally:
        proc.terminate()
        proc.wait(10)
