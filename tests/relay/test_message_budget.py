"""No valid message costs a relay more than a small multiple of its size, or stalls another
robot's viewers (issue 53, finding 2), against real processes.

A relay (its own process, a Zenoh router) serves robot1, a played robot putting messages of
``bomb_msgs/msg/Bomb`` (tests/relay/played_bomb.py), and robot2, a played robot putting
``/steady`` at 20 Hz with its send time, which a viewer in this process watches for its
latency. The readers of robot1's ``/bomb`` run in their own process (what they are sent
would stall this process's loop, not the relay's).

- The red team's bomb, 4 MiB of one-byte structs (~1 GB decoded) with a JSON reader: the
  relay refuses it at its sequence's count (logged with the robot, the topic, the field and
  the budget), its peak RSS rises by less than 20 times the message plus 64 MiB, robot2's
  viewer is never a second late, and the message after it reaches the reader.
- Valid 6 MiB messages of points (~13 times their size decoded), read as JSON, CBOR and
  ``cbor-raw``: each reader gets each of them (the raw one the bytes as they came), robot2's
  viewer is never two seconds late (they are decoded off the loop; 6.2 s before), and the
  peak RSS bound holds.
"""

from __future__ import annotations

import asyncio
import re
import sys
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from typing import Any

import pytest

from tests.helpers import ROOT, WireClient, open_wire, peak_rss, ros_env
from tests.relay.played_bomb import BOMB, bomb_of
from tests.relay.procs import Proc
from tests.relay.support import free_port

pytestmark = pytest.mark.timeout(120)

LATE = 1.0
"""Seconds robot2's viewer may get a message after it was put, at most, while a bomb is
refused (0.01-0.04 s measured at load 10 on 2 cores; 31 s before the budget)."""
LATE_DECODING = 2.0
"""And while valid large messages are decoded on a worker thread, which shares Python's lock
with the loop (0.18-1.06 s measured at load 10 on 2 cores; 6.2 s when they were decoded on
the loop)."""
PER_BYTE = 20
"""Peak RSS the relay may add per byte of the message (the issue's target)."""
SLACK = 64 * 2**20
"""And besides, whatever the message."""
READY = re.compile(r"relay listening on ws://127\.0\.0\.1:(\d+)")

READER = """
import asyncio, json, sys
from websockets.asyncio.client import connect

async def read(url, compression):
    async with connect(url, max_size=None) as ws:
        await ws.send(json.dumps({"op": "subscribe", "topic": "/bomb", "type": sys.argv[2],
                                  "compression": compression}))
        print("subscribed", compression, flush=True)
        async for frame in ws:
            print("frame", compression, len(frame), flush=True)

async def main():
    await asyncio.gather(*(read(sys.argv[1], c) for c in sys.argv[3:]))

asyncio.run(main())
"""
"""Readers of robot1's /bomb in their own process: each prints the size of what it gets."""


@dataclass
class Relay:
    proc: Proc
    port: int
    router: str
    played: list[asyncio.subprocess.Process] = field(default_factory=list)


@asynccontextmanager
async def relay_with_robots(mode: str, mib: float) -> AsyncIterator[tuple[Relay, Any]]:
    """A relay process serving robot1 (played ``mode``) and robot2 (``clock``)."""
    router = f"tcp/127.0.0.1:{free_port()}"
    relay = Relay(Proc([sys.executable, "-m", "bridge_server.zenoh.relay", "--port", "0",
                        "--zenoh-listen", router], ros_env()), 0, router)
    try:
        relay.port = int(relay.proc.wait_for(READY).group(1))
        bomber = await _played(relay, "robot1", mode, mib)
        await _played(relay, "robot2", "clock", 0)
        yield relay, bomber
    finally:
        for proc in relay.played:
            if proc.stdin is not None:
                proc.stdin.close()
            try:
                await asyncio.wait_for(proc.wait(), 10)
            except TimeoutError:
                proc.kill()
                await proc.wait()
        relay.proc.stop()


async def _played(relay: Relay, robot: str, mode: str, mib: float) -> asyncio.subprocess.Process:
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "tests.relay.played_bomb", relay.router, robot, mode, str(mib),
        cwd=ROOT, env=ros_env(), stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE)
    relay.played.append(proc)
    assert await _line(proc) == "ready"
    return proc


async def _line(proc: asyncio.subprocess.Process, timeout: float = 60) -> str:
    assert proc.stdout is not None
    return (await asyncio.wait_for(proc.stdout.readline(), timeout)).decode().strip()


async def _viewer(relay: Relay) -> WireClient:
    """robot2's viewer of /steady, once it gets messages (robot2 is served)."""
    deadline = time.monotonic() + 30
    while True:
        try:
            viewer = await open_wire(f"ws://127.0.0.1:{relay.port}/robot2")
            break
        except Exception:  # robot2 not served yet (the relay answers 503 or 404)
            assert time.monotonic() < deadline, "the relay never served robot2"
            await asyncio.sleep(0.2)
    await viewer.send({"op": "subscribe", "topic": "/steady", "type": "std_msgs/msg/String"})
    await viewer.expect(op="publish", topic="/steady", timeout=30)
    return viewer


class Watch:
    """Reads robot2's viewer all along: (send time, how late) of each /steady message."""

    def __init__(self, viewer: WireClient) -> None:
        self.viewer = viewer
        self.seen: list[tuple[float, float]] = []
        self.task = asyncio.ensure_future(self._read())

    async def _read(self) -> None:
        while True:
            op = await self.viewer.expect(op="publish", topic="/steady", timeout=60)
            sent = float(op["msg"]["data"])
            self.seen.append((sent, time.time() - sent))

    async def late_since(self, start: float, until: asyncio.Future[Any]) -> list[float]:
        """How late each message put since ``start`` (``time.time()``) was, until ``until``
        is done and half a second more."""
        await until
        await asyncio.sleep(0.5)
        assert not self.task.done(), self.task
        return [late for sent, late in self.seen if sent >= start]

    async def close(self) -> None:
        self.task.cancel()
        await self.viewer.close()


async def _readers(relay: Relay, *compressions: str) -> asyncio.subprocess.Process:
    """The readers of robot1's /bomb, subscribed (robot1 served)."""
    deadline = time.monotonic() + 30
    while True:
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-c", READER, f"ws://127.0.0.1:{relay.port}/robot1", BOMB,
            *compressions, cwd=ROOT, env=ros_env(), stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.DEVNULL)
        lines = [await _line(proc, 30) for _ in compressions]
        if all(line.startswith("subscribed") for line in lines):
            relay.played.append(proc)
            return proc
        await proc.wait()  # robot1 not served yet: refused
        assert time.monotonic() < deadline, f"the readers never subscribed: {lines}"
        await asyncio.sleep(0.2)


async def _frames(readers: asyncio.subprocess.Process, count: int) -> list[tuple[str, int]]:
    """The next ``count`` frames the readers print: (compression, size)."""
    out = []
    for _ in range(count):
        _, compression, size = (await _line(readers)).split()
        out.append((compression, int(size)))
    return out


async def _heard(readers: asyncio.subprocess.Process, bomber: Any, *compressions: str) -> None:
    """Put small messages until every reader got one (the relay's subscription is up), and
    until none is in flight."""
    assert bomber.stdin is not None
    heard: set[str] = set()
    deadline = time.monotonic() + 30
    while True:
        bomber.stdin.write(b"small\n")
        await bomber.stdin.drain()
        await _line(bomber)
        try:
            while True:
                heard.add((await _line(readers, 1.0)).split()[1])
        except TimeoutError:
            if heard == set(compressions):
                return
        assert time.monotonic() < deadline, f"only {heard} heard robot1"


async def test_a_bomb_of_one_byte_structs_is_refused_at_its_count(ros_node: Any) -> None:
    """4 MiB of one-byte structs for a JSON reader: refused (logged naming robot1, /bomb, the
    field and the budget) with the relay's peak RSS under 20x the message + 64 MiB, robot2's
    viewer never LATE seconds behind, and the small message after it delivered."""
    mib = 4.0
    async with relay_with_robots("tiny", mib) as (relay, bomber):
        watch = Watch(await _viewer(relay))
        readers = await _readers(relay, "none")
        await _heard(readers, bomber, "none")
        before, start = peak_rss(relay.proc.proc.pid), time.time()
        assert bomber.stdin is not None
        bomber.stdin.write(b"go\ngo\n")
        await bomber.stdin.drain()
        done = asyncio.ensure_future(_frames(readers, 2))  # the two small ones after the bombs
        late = await watch.late_since(start, done)
        frames = await done
        rise = peak_rss(relay.proc.proc.pid) - before
        print(f"tiny bomb of {mib} MiB: peak RSS +{rise / 2**20:.0f} MiB, robot2's viewer at "
              f"most {max(late):.3f} s late")
        assert all(size < 4096 for _, size in frames), frames  # the bombs never reached it
        assert rise < PER_BYTE * len(bomb_of("tiny", mib)) + SLACK, (
            f"the relay's peak RSS rose by {rise / 2**20:.0f} MiB")
        assert max(late) < LATE, f"robot2's viewer was {max(late):.2f} s late"
        logged = relay.proc.wait_for(re.compile(r"robot robot1: messages of /bomb .*over the "
                                                r"decode budget"))
        assert "'tiny'" in logged.string and "--decode-budget-per-byte" in logged.string
        await watch.close()


async def test_large_valid_messages_delay_only_their_own_topic(ros_node: Any) -> None:
    """Three 6 MiB messages of points read as JSON, CBOR and cbor-raw: every reader gets
    every one (cbor-raw its bytes as they came), robot2's viewer is never LATE_DECODING
    seconds behind, and the relay's peak RSS stays under 20x the message + 64 MiB."""
    mib = 6.0
    size = len(bomb_of("points", mib))
    async with relay_with_robots("points", mib) as (relay, bomber):
        watch = Watch(await _viewer(relay))
        readers = await _readers(relay, "none", "cbor", "cbor-raw")
        await _heard(readers, bomber, "none", "cbor", "cbor-raw")
        before, start = peak_rss(relay.proc.proc.pid), time.time()
        assert bomber.stdin is not None
        bomber.stdin.write(b"go\n" * 3)
        await bomber.stdin.drain()
        done = asyncio.ensure_future(_frames(readers, 3 * 2 * 3))  # 3 readers, 3 x big+small
        late = await watch.late_since(start, done)
        frames = await done
        rise = peak_rss(relay.proc.proc.pid) - before
        print(f"points of {mib} MiB: peak RSS +{rise / 2**20:.0f} MiB, robot2's viewer at "
              f"most {max(late):.3f} s late")
        big = sorted(c for c, n in frames if n > size // 2)
        assert big == sorted(["none", "cbor", "cbor-raw"] * 3), frames
        assert min(n for c, n in frames if c == "cbor-raw" and n > size // 2) > size
        assert max(late) < LATE_DECODING, f"robot2's viewer was {max(late):.2f} s late"
        assert rise < PER_BYTE * size + SLACK, (
            f"the relay's peak RSS rose by {rise / 2**20:.0f} MiB")
        await watch.close()
