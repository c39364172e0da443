"""Clear answers through a relay: an offline or misspelt robot, a refused token or role.

A real relay (the Zenoh router) and real robots (rclpy bridges dialing out to it); clients
are ours, the command-line tool, and the relay's own handshake answers.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import socket
import sys
from pathlib import Path

import pytest

import roslibpy_lite
from roslibpy_lite.cli import main as cli_main
from roslibpy_lite.cli.common import EXIT_CONNECT
from roslibpy_lite.exceptions import ConnectError, NotAuthenticated
from tests.helpers import ros_env

from .support import (
    ROBOT,
    ROBOT1_VIEWER,
    free_port,
    relay_with_auth,
    robot_reachable,
    start_relay,
    start_robot,
    until,
)

RUNNING = "is the bridge running?"


async def _cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str]:
    """Run the command-line tool (its own event loop, in a thread); its status and stderr."""
    capsys.readouterr()
    code = await asyncio.to_thread(cli_main, list(argv))
    return code, capsys.readouterr().err


async def test_an_offline_robot_fails_at_once_with_the_relays_words(
        capsys: pytest.CaptureFixture[str]) -> None:
    """A robot the relay does not have: connect fails on its first answer (one refusal
    counted, not an open_timeout of retries), saying the relay answered and what it said;
    the CLI prints that line without asking whether the bridge runs."""
    relay = await start_relay(listen=f"tcp/127.0.0.1:{free_port()}")
    try:
        url = f"ws://127.0.0.1:{relay.port}/robot9"
        with pytest.raises(ConnectError) as caught:
            await roslibpy_lite.connect(url, open_timeout=30.0)
        text = str(caught.value)
        assert caught.value.refused == 404
        assert f"the relay at {url} (robot 'robot9') answered HTTP 404" in text, text
        assert "no robot named 'robot9' is connected to this relay's Zenoh network" in text
        assert "is the port right" not in text
        assert relay.refused == {"unknown_robot": 1}  # asked once, not retried

        code, err = await _cli(capsys, "topic", "list", "--url", url, "--timeout", "30")
        assert code == EXIT_CONNECT, err
        assert "no robot named 'robot9'" in err and RUNNING not in err, err
        assert relay.refused == {"unknown_robot": 2}
    finally:
        await relay.close()


async def test_wait_for_robot_connects_once_the_robot_arrives() -> None:
    """``wait_for_robot=True``: the relay's "not connected" answers are retried, and the
    client connects once the robot dials in."""
    router = f"tcp/127.0.0.1:{free_port()}"
    relay = await start_relay(listen=router)
    started = None
    try:
        url = f"ws://127.0.0.1:{relay.port}/{ROBOT}"
        opening = asyncio.ensure_future(
            roslibpy_lite.connect(url, open_timeout=60.0, wait_for_robot=True))
        await until(lambda: opening.done() or relay.refused.get("unknown_robot", 0) >= 2,
                    "the relay to refuse the client twice")  # refused, and asked again
        assert not opening.done(), opening
        started = await start_robot(router)
        await robot_reachable(relay)
        ros = await opening
        try:
            assert ROBOT in str(ros.url)
            assert "/rosapi/topics" in [s.name for s in await ros.graph.services()]
        finally:
            await ros.close()
    finally:
        await relay.close()
        if started is not None:
            await started[1].close()
            await started[0].close()


async def test_refused_token_and_role_say_relay_and_not_running(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A wrong token (401) and a role that may not reach the robot (403): the errors say the
    relay refused and why, and the CLI adds no "is the bridge running?"."""
    async with relay_with_auth(tmp_path / "auth.toml", ROBOT1_VIEWER) as (relay, tokens):
        base = f"ws://127.0.0.1:{relay.port}"
        with pytest.raises(NotAuthenticated) as bad:
            await roslibpy_lite.connect(f"{base}/robot1", token="not-a-token", open_timeout=10)
        assert bad.value.refused == 401
        assert f"the relay at {base}/robot1 (robot 'robot1') refused our token" in str(bad.value)
        with pytest.raises(ConnectError) as other:
            await roslibpy_lite.connect(f"{base}/robot2", token=tokens["robot1_viewer"],
                                        open_timeout=10)
        assert other.value.refused == 403
        assert "the relay at" in str(other.value)
        assert "may not reach robot 'robot2'" in str(other.value)

        for url, token in ((f"{base}/robot1", "not-a-token"),
                           (f"{base}/robot2", tokens["robot1_viewer"])):
            code, err = await _cli(capsys, "topic", "list", "--url", url, "--token", token)
            assert code == EXIT_CONNECT and "the relay at" in err and RUNNING not in err, err
            assert tokens["robot1_viewer"] not in err


async def test_nothing_listening_still_asks_whether_the_bridge_runs(
        capsys: pytest.CaptureFixture[str]) -> None:
    """Where nothing answered, the CLI's hint stays (only a server's own "no" drops it)."""
    with contextlib.closing(socket.socket()) as s:
        s.bind(("127.0.0.1", 0))
        url = f"ws://127.0.0.1:{s.getsockname()[1]}/robot1"  # bound, never listening
        code, err = await _cli(capsys, "topic", "list", "--url", url, "--timeout", "1")
    assert code == EXIT_CONNECT and RUNNING in err, err


STOCK_ROSLIBPY = """
import json, os, roslibpy
ros = roslibpy.Ros(host=os.environ["URL"],
                   headers={"Authorization": "Bearer " + os.environ["TOKEN"]})
ros.run(timeout=20)
print(json.dumps({"topics": ros.get_topics()}), flush=True)
ros.terminate()
"""


async def test_stock_roslibpy_takes_a_relays_url_with_a_token(tmp_path: Path) -> None:
    """The relay guide's stock roslibpy form (a whole URL as ``host``, the token in
    ``headers``) reaches the robot through a relay that requires a token."""
    async with relay_with_auth(tmp_path / "auth.toml", ROBOT1_VIEWER, robots=("robot1",)) as (
            relay, tokens):
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-c", STOCK_ROSLIBPY, stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.STDOUT,
            env=ros_env(URL=f"ws://127.0.0.1:{relay.port}/robot1", TOKEN=tokens["robot1_viewer"]))
        try:
            out, _ = await asyncio.wait_for(proc.communicate(), 60)
        finally:
            if proc.returncode is None:
                proc.kill()
                await proc.wait()
        text = out.decode()
        assert proc.returncode == 0, text
        assert "/rosout" in json.loads(text.strip().splitlines()[-1])["topics"], text
