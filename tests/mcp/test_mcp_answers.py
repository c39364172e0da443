"""MCP answers an agent (and its operator) can act on, against real processes: a bad token
names the file it came from, and a robot not up at start is waited for and said so in the
log, not the end of the server."""

from __future__ import annotations

import json
import re
import subprocess
import time
from collections.abc import Callable
from pathlib import Path

from mcp import Client

from roslibpy_lite import MockRos
from roslibpy_lite.mcp import build_server
from tests.helpers import ROOT, BridgeProcess, free_port, ros_env
from tests.mcp.http_support import attempt, start_args
from tests.mcp.support import text
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


def _relay_says(ros: MockRos, level: str, text: str) -> None:
    """A status op as a relay sends it to its clients, delivered to ``ros``."""
    ros._bridge._deliver(json.dumps({"op": "status", "level": level, "msg": text}))


async def test_a_robot_away_is_named_in_errors_and_graph_answers() -> None:
    """After the relay's "robot went away" a read that times out says the robot is away (with
    the relay's words and the age) and list_topics says its graph is the relay's last view;
    after "is back" neither does."""
    ros = MockRos()
    await ros.advertise("/chatter", "std_msgs/msg/String")
    async with Client(build_server(ros)) as client:
        _relay_says(ros, "warning", "robot robot1 went away: its link to the Zenoh network "
                                    "dropped")
        result = await client.call_tool("read_topic", {"topic": "/chatter", "timeout": 0.2})
        assert result.is_error, text(result)
        assert re.search(r"no answer within the timeout; the robot is away \(\d+ s ago the "
                         "relay said: robot robot1 went away", text(result)), text(result)
        listing = await client.call_tool("list_topics", {})
        assert "this graph is the relay's last view" in text(listing).split("\n", 1)[0]
        assert "/chatter" in text(listing)
        _relay_says(ros, "info", "robot robot1 is back: its topics flow again")
        result = await client.call_tool("read_topic", {"topic": "/chatter", "timeout": 0.2})
        assert "away" not in text(result)
        assert "last view" not in text(await client.call_tool("list_topics", {}))
