"""``bag record`` stopped by SIGINT or SIGTERM at any point of its life (issue 43: a recorder
stopped while it started left a 42-byte file, magic and header only, and said nothing):
it always leaves a finished file that our reader and the independent one (mcap,
mcap-ros2-support) read, says what it recorded, and exits 0. Each point is reached by
watching the recorder (its lines, its connections, its file), not by waiting blindly."""

from __future__ import annotations

import asyncio
import os
import re
import signal
import subprocess
import sys
import threading
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from sensor_msgs.msg import Image as RosImage
from websockets.asyncio.server import ServerConnection, serve

from roslibpy_lite.bag import info, read
from tests.helpers import ROOT, BridgeProcess, free_port, ros_env

SIGNALS = {"sigint": signal.SIGINT, "sigterm": signal.SIGTERM}
RECORDED = re.compile(r"^recorded (\S+): (\d+) topics, (\d+) msgs")


class Recording:
    """``roslibpy-lite bag record`` in its own process; what it prints (stdout and stderr)
    is kept, and shown when a test fails."""

    def __init__(self, url: str, topic: str, path: Path, *extra: str) -> None:
        self.path = path
        self.lines: list[str] = []
        self._seen = threading.Condition()
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "roslibpy_lite.cli", "bag", "record", topic, "-o", str(path),
             "--url", url, *extra],
            cwd=ROOT, env=ros_env(), stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT, text=True)
        self._pump = threading.Thread(target=self._read, daemon=True)
        self._pump.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            with self._seen:
                self.lines.append(line.rstrip("\n"))
                self._seen.notify_all()
        self.proc.stdout.close()
        with self._seen:
            self._seen.notify_all()

    def _wait_for(self, pattern: re.Pattern[str]) -> None:
        with self._seen:
            assert self._seen.wait_for(
                lambda: any(pattern.search(x) for x in self.lines) or not self._pump.is_alive(),
                30), self.output()
        assert any(pattern.search(x) for x in self.lines), self.output()

    async def line(self, pattern: str) -> None:
        """Until the recorder prints a line matching ``pattern``."""
        await asyncio.to_thread(self._wait_for, re.compile(pattern))

    async def stop(self, sig: int) -> tuple[int, int]:
        """Send ``sig``; its exit status and the message count its last line gives."""
        self.proc.send_signal(sig)
        status = await asyncio.to_thread(self.proc.wait, 30)
        await asyncio.to_thread(self._pump.join, 10)  # all it printed
        match = RECORDED.search(self.lines[-1]) if self.lines else None
        assert match is not None and match.group(1) == str(self.path), self.output()
        return status, int(match.group(3))

    def kill(self) -> None:
        """Kill it if it still runs."""
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        self._pump.join(10)

    def output(self) -> str:
        """What it printed, and how it ended."""
        return "\n".join(self.lines) + f"\n(exit status {self.proc.poll()})"


@pytest.fixture
async def recordings() -> AsyncIterator[Callable[..., Recording]]:
    """Recorders started by the test; any left running is stopped afterwards."""
    made: list[Recording] = []

    def start(*args: Any) -> Recording:
        made.append(Recording(*args))
        return made[-1]

    yield start
    for rec in made:
        rec.kill()


def _readable(path: Path, messages: int) -> None:
    """``path`` is a finished MCAP file with ``messages`` messages, for both readers."""
    about = info(path)
    assert about.complete and about.messages == messages == len(list(read(path))), about
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        assert summary.statistics.message_count == messages
        assert len(list(reader.iter_decoded_messages())) == messages


async def _stopped_cleanly(rec: Recording, sig: int) -> int:
    status, messages = await rec.stop(sig)
    assert status == 0, rec.output()
    _readable(rec.path, messages)
    return messages


@pytest.mark.parametrize("how", list(SIGNALS))
async def test_stopped_right_after_its_first_line_while_no_bridge_is_up(
        recordings: Callable[..., Recording], tmp_path: Path, how: str) -> None:
    """Signalled as soon as it says it is connecting, to a port where no bridge is up yet
    (it retries): an empty finished file, "0 msgs"."""
    rec = recordings(f"ws://127.0.0.1:{free_port()}", "/nothing", tmp_path / "early.mcap",
                     "--timeout", "30")
    await rec.line(r"^recording to .*: connecting to ws://")
    assert await _stopped_cleanly(rec, SIGNALS[how]) == 0


@pytest.mark.parametrize("how", list(SIGNALS))
async def test_stopped_while_the_bridge_has_not_answered_the_handshake(
        recordings: Callable[..., Recording], tmp_path: Path, how: str) -> None:
    """Signalled once its TCP connection is accepted by a server that never answers the
    websocket handshake: an empty finished file."""
    reached = asyncio.Event()
    held: list[asyncio.StreamWriter] = []

    async def hold(_: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        held.append(writer)
        reached.set()

    server = await asyncio.start_server(hold, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    try:
        rec = recordings(f"ws://127.0.0.1:{port}", "/nothing", tmp_path / "handshake.mcap",
                         "--timeout", "30")
        await asyncio.wait_for(reached.wait(), 30)
        assert await _stopped_cleanly(rec, SIGNALS[how]) == 0
    finally:
        server.close()
        for writer in held:
            writer.close()


@pytest.mark.parametrize("how", list(SIGNALS))
async def test_stopped_while_it_waits_for_the_bridges_first_answer(
        recordings: Callable[..., Recording], tmp_path: Path, how: str) -> None:
    """Signalled once a websocket peer that never answers got its first request (the
    recorder is starting: the file is open, it asks for the topics): the file is finished,
    not left as a header (issue 43's 42-byte file)."""
    asked = asyncio.Event()

    async def silent(ws: ServerConnection) -> None:
        await ws.recv()
        asked.set()
        await ws.wait_closed()

    async with serve(silent, "127.0.0.1", 0) as server:
        port = next(iter(server.sockets)).getsockname()[1]
        rec = recordings(f"ws://127.0.0.1:{port}", "/nothing", tmp_path / "starting.mcap",
                         "--timeout", "30")
        await asyncio.wait_for(asked.wait(), 30)
        assert await _stopped_cleanly(rec, SIGNALS[how]) == 0


@pytest.mark.parametrize("how", list(SIGNALS))
async def test_stopped_while_it_waits_for_a_topic_nobody_publishes(
        recordings: Callable[..., Recording], bridge: BridgeProcess, topic: str,
        tmp_path: Path, how: str) -> None:
    """Signalled once it says it waits for the topic (connected, nothing published): an
    empty finished file."""
    rec = recordings(bridge.url, topic, tmp_path / "waiting.mcap")
    await rec.line(rf"^recording 0 topic\(s\); waiting for {re.escape(topic)}$")
    assert await _stopped_cleanly(rec, SIGNALS[how]) == 0


@pytest.mark.parametrize("how", list(SIGNALS))
async def test_stopped_mid_write_while_messages_flow(
        recordings: Callable[..., Recording], bridge: BridgeProcess, ros_node: Any,
        topic: str, tmp_path: Path, how: str) -> None:
    """Signalled while images flow and its first chunks are on disk: every message it
    counted is in the finished file, intact."""
    path = tmp_path / "flowing.mcap"
    pub = ros_node.create_publisher(RosImage, topic, 10)
    sent: dict[str, bytes] = {}

    def publish() -> None:
        msg = RosImage(height=48, width=64, encoding="rgb8", step=64 * 3)
        msg.header.frame_id = f"cam{len(sent)}"
        msg.data = sent[msg.header.frame_id] = os.urandom(64 * 48 * 3)  # no compression
        pub.publish(msg)

    rec = recordings(bridge.url, topic, path)
    # 256 KiB chunks: a few dozen 9 KiB images put the first one on disk
    await _publishing_until(lambda: path.exists() and path.stat().st_size > 300_000, publish)
    messages = await _stopped_cleanly(rec, SIGNALS[how])
    assert messages > 0
    frames = [m.decode() for m in read(path)]
    assert all(f.data == sent[f.header.frame_id] for f in frames)  # type: ignore[attr-defined]


async def _publishing_until(condition: Callable[[], bool], publish: Callable[[], None],
                            timeout: float = 30) -> None:
    """Publish every 20 ms until ``condition()`` (the recorder's subscription matches on
    its own time: discovery has no event to await)."""
    async def loop() -> None:
        while not condition():
            publish()
            await asyncio.sleep(0.02)

    await asyncio.wait_for(loop(), timeout)


async def test_a_recorder_stopped_before_it_started_leaves_an_empty_file(tmp_path: Path) -> None:
    """``Recorder.stop()`` with no ``start()`` (one cancelled before its first step) still
    writes a finished, empty file."""
    from roslibpy_lite import MockRos
    from roslibpy_lite.bag import Recorder

    path = tmp_path / "never.mcap"
    stats = await Recorder(MockRos(), path, topics={"/a": "std_msgs/msg/Int32"}).stop()
    assert stats.files == [path] and stats.messages == 0
    _readable(path, 0)
