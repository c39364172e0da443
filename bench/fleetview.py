"""Many fleet viewers in one process: each watches 1-3 simulated robots through a relay.

A viewer is one rosbridge websocket connection per robot it watches (``ws://HOST/ROBOT``),
subscribed to one topic of :mod:`bench.simrobot`: ``/status`` (1 Hz, JSON text with its
number and time), ``/pose`` (10 Hz: ``x`` is its number, the stamp its time) or the camera
(``cbor-raw``, counted only; so is ``/flood``). A connection that closes (its relay killed)
dials the same address again (the balancer) and subscribes again, as a client that restores
its subscriptions does, after the delays of roslibpy-lite's own client
(:class:`roslibpy_lite.Backoff`: 0.1 s, doubling to 5 s while dials fail, from 0.1 s again
once one opens). A fixed half-second made the viewers of a fleet whose balancer had no relay
to offer dial a million times in ten minutes, on the cores the tier they measure runs on.

Per connection it keeps: seconds to open (the websocket handshake: the relay has opened
the robot), seconds to the first message, the numbers got, missed (gaps) and repeated, the
latency of numbered messages (wall clock: robots and viewers share the machine), and the
first arrival after a mark (recovery after a kill). Run as a program
(``python -m bench.fleetview URL PLAN_JSON``; the plan a list of ``[robots, topic]``), it
prints ``{"event": "ready"}`` once every connection got a message (or ``--wait`` passed),
then answers each stdin line (``stats``, ``reset``, ``mark``) with one JSON line.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import random
import sys
import time
from typing import Any

import websockets
from websockets.asyncio.client import connect

from bench.fleetproc import json_lines
from roslibpy_lite import Backoff

__all__ = ["Conn", "main"]

RAMP_BATCH = 50
"""Connections dialed together, ``--ramp`` s apart."""
LATENCY_KEEP = 2000
"""Latency samples kept per robot (every n-th beyond that)."""

odd: str | None = None
"""The first message a viewer could not read (with its robot and topic), counted as
``malformed``: a message the relay should not have sent."""


class Conn:
    """One viewer's connection to one robot (see the module's text)."""

    def __init__(self, base: str, robot: str, topic: str) -> None:
        self.url = f"{base}/{robot}"
        self.robot = robot
        self.topic = topic
        self.open_s: float | None = None
        self.first_s: float | None = None
        self.last_seq: int | None = None
        self.got = self.missed = self.repeated = self.frames = self.malformed = 0
        self.latency_ms: list[float] = []
        self.mark: float | None = None
        self.back_s: float | None = None
        self.reconnects = 0
        self.heard = asyncio.Event()

    def subscribe_op(self) -> str:
        """The subscribe op of this connection's topic."""
        return json.dumps({"op": "subscribe", "topic": self.topic, "queue_length": 2,
                           **({} if self.counted else {"compression": "cbor-raw"})})

    @property
    def counted(self) -> bool:
        """Whether its messages are numbered (``/pose``, ``/status``); others (the camera,
        ``/flood``) come as ``cbor-raw`` and are counted only."""
        return self.topic in ("/pose", "/status")

    async def run(self) -> None:
        """Connect, subscribe, count; dial again when closed, for ever."""
        backoff = Backoff()
        while True:
            t0 = time.monotonic()
            try:
                async with connect(self.url, open_timeout=120, max_size=2**24,
                                   ping_interval=None, compression=None) as ws:
                    if self.open_s is None:
                        self.open_s = time.monotonic() - t0
                    backoff.reset()
                    await ws.send(self.subscribe_op())
                    async for data in ws:
                        try:
                            self._on(data, t0)
                        except (KeyError, TypeError, ValueError) as exc:  # counted, one kept
                            self.malformed += 1
                            global odd
                            odd = odd or f"{self.robot} {self.topic}: {exc!r}: {data[:400]!r}"
            except (OSError, websockets.WebSocketException, TimeoutError):
                pass
            self.reconnects += 1
            await asyncio.sleep(backoff.next())

    def _on(self, data: str | bytes, t0: float) -> None:
        now = time.monotonic()
        if isinstance(data, bytes) or not self.counted:  # cbor-raw: counted, not decoded
            self.frames += 1
            self._arrived(now, t0)
            return
        msg = json.loads(data)
        if msg.get("op") != "publish":
            return
        body = msg["msg"]
        if self.topic == "/pose":
            seq = int(body["pose"]["position"]["x"])
            stamp = body["header"]["stamp"]
            sent_ns = stamp["sec"] * 1_000_000_000 + stamp["nanosec"]
        else:
            status = json.loads(body["data"])
            seq, sent_ns = int(status["seq"]), int(status["t"])
        self._arrived(now, t0)
        if self.last_seq is not None and seq <= self.last_seq:
            self.repeated += 1
            return
        if self.last_seq is not None:
            self.missed += seq - self.last_seq - 1
        self.last_seq = seq
        self.got += 1
        lat = (time.time_ns() - sent_ns) / 1e6
        if len(self.latency_ms) < LATENCY_KEEP:
            self.latency_ms.append(lat)
        else:
            self.latency_ms[random.randrange(LATENCY_KEEP)] = lat

    def _arrived(self, now: float, t0: float) -> None:
        if self.first_s is None:
            self.first_s = now - t0
        if self.mark is not None and self.back_s is None:
            self.back_s = time.time() - self.mark
        self.heard.set()

    def reset(self) -> None:
        """Start a new measurement window (the sequence carries on)."""
        self.got = self.missed = self.repeated = self.frames = self.malformed = 0
        self.latency_ms = []


def stats(conns: list[Conn]) -> dict[str, Any]:
    """What the connections measured, by robot, and their open and recovery times."""
    robots: dict[str, dict[str, Any]] = {}
    for c in conns:
        r = robots.setdefault(c.robot, {"got": 0, "missed": 0, "repeated": 0, "frames": 0,
                                        "malformed": 0, "latency_ms": [], "viewers": 0})
        r["viewers"] += 1
        for k in ("got", "missed", "repeated", "frames", "malformed"):
            r[k] += getattr(c, k)
        r["latency_ms"] += c.latency_ms
    for r in robots.values():  # at most LATENCY_KEEP samples a robot go back
        lat = r["latency_ms"]
        if len(lat) > LATENCY_KEEP:
            r["latency_ms"] = random.sample(lat, LATENCY_KEEP)
    return {"event": "stats", "robots": robots,
            "open_s": [c.open_s for c in conns if c.open_s is not None],
            "first_s": [c.first_s for c in conns if c.first_s is not None],
            "back_s": [c.back_s for c in conns if c.mark is not None],
            "silent": sum(c.first_s is None for c in conns),
            "reconnects": sum(c.reconnects for c in conns), "odd": odd}


async def _serve(args: argparse.Namespace) -> int:
    say = json_lines()
    plan = json.loads(args.plan)
    conns = [Conn(args.url, robot, topic) for robots, topic in plan for robot in robots]
    tasks = []
    for k in range(0, len(conns), RAMP_BATCH):  # a ramp, as viewers arrive, not all at once
        tasks += [asyncio.create_task(c.run()) for c in conns[k:k + RAMP_BATCH]]
        await asyncio.sleep(args.ramp)
    with contextlib.suppress(TimeoutError):
        async with asyncio.timeout(args.wait):
            await asyncio.gather(*(c.heard.wait() for c in conns))
    say({"event": "ready", "connections": len(conns),
         "silent": sum(not c.heard.is_set() for c in conns)})
    loop = asyncio.get_running_loop()
    reader = asyncio.StreamReader()
    await loop.connect_read_pipe(lambda: asyncio.StreamReaderProtocol(reader), sys.stdin)
    while line := await reader.readline():
        cmd = json.loads(line)
        if cmd["cmd"] == "reset":
            for c in conns:
                c.reset()
            say({"event": "reset"})
        elif cmd["cmd"] == "mark":
            for c in conns:
                c.mark, c.back_s = float(cmd["t"]), None
            say({"event": "marked"})
        else:
            say(stats(conns))
    for t in tasks:
        t.cancel()
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run the viewers of ``PLAN`` against ``URL`` until stdin closes."""
    p = argparse.ArgumentParser(prog="python -m bench.fleetview", description=__doc__)
    p.add_argument("url", help="the balancer's (or a relay's) ws://HOST:PORT")
    p.add_argument("plan", help='JSON list of [robots, topic], e.g. [[["sim-1"], "/pose"]]')
    p.add_argument("--ramp", type=float, default=0.05,
                   help=f"seconds between two batches of {RAMP_BATCH} dials")
    p.add_argument("--wait", type=float, default=120.0,
                   help="seconds to wait for every connection's first message")
    return asyncio.run(_serve(p.parse_args(argv)))


if __name__ == "__main__":
    sys.exit(main())
