"""Simulated robots for the fleet benchmark and its test: the real robot side, no ROS.

Each :class:`SimRobot` is a ROS graph in memory (:class:`~rosbridge_core.memory.graph.MemoryRos`)
shaped like a small mobile robot's: 30 nodes, 100 topics, 20 services (15 of them the
parameter services of 5 nodes with parameters), one action (``/navigate``, the
``test_msgs/action/Fibonacci`` type). Its relay side is the bridge's own
:class:`~bridge_server.zenoh.exporter.Exporter` on one node of that graph, with its own Zenoh
session, name claim and replay window: nothing of the robot side is written again here.

Traffic: an IMU at 100 Hz, odometry at 50 Hz, a pose at 10 Hz (``/pose``: its ``x`` is the
message's number and its stamp the wall clock, so a viewer counts what it missed and how
late it came), a status at 1 Hz, a 640x480 rgb8 camera at 10 Hz. A topic is published only
while some relay watches it (the exporter has subscribed it): a ROS publisher with no
matched reader sends nothing over the wire either, so an unwatched robot costs its relays
nothing but its presence. One asyncio task ticks every robot of the process (no task per
robot and topic): many robots fit in one process.

Run as a program (``python -m bench.simrobot --connect tcp/127.0.0.1:7447 --count 50``) it
starts ``--count`` robots named ``PREFIX-<i>``, prints ``{"event": "ready", ...}`` when
every robot holds its name on Zenoh, then obeys one JSON command a line on stdin
(:meth:`Fleet.command`) and answers each with one JSON line; it ends when stdin closes.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import logging
import os
import sys
import time
from dataclasses import dataclass, field
from typing import Any

from bench.fleetproc import json_lines
from bridge_server.zenoh.exporter import Exporter
from bridge_server.zenoh.link import ZenohOptions
from bridge_server.zenoh.robot_link import RobotOptions
from msgs import dynamic
from rosbridge_core.memory.graph import MemoryGraph, MemoryPublisher, MemoryRos
from rosbridge_core.protocol.goal_status import GoalStatus

__all__ = ["CAMERA", "POSE", "STREAMS", "Fleet", "SimRobot", "Stream", "main"]

POSE = "/pose"
"""The counted topic: ``pose.position.x`` is the message's number, the stamp its time."""
CAMERA = "/camera/image_raw"
FLOOD = "/flood"
"""A topic a robot publishes only when told to flood (:meth:`Fleet.command` ``flood``)."""
NODES = 30
TOPICS = 100
PARAM_NODES = 5
SNAPSHOT_INTERVAL = 300.0
"""Seconds between the exporter's graph snapshots of a simulated robot (the bridge's 1 s
looks for graph changes; a simulated graph does not change, and 1,000 robots each walking
their graph every second would measure the simulator: at 30 s, taking the in-memory graph's
snapshot was 60 % of a 250-robot process's loop while 1,000 robots joined)."""


@dataclass(frozen=True)
class Stream:
    """One published topic of a simulated robot: its name, type and rate."""

    topic: str
    type_name: str
    hz: float


STREAMS = (
    Stream("/imu", "sensor_msgs/msg/Imu", 100.0),
    Stream("/odom", "nav_msgs/msg/Odometry", 50.0),
    Stream(POSE, "geometry_msgs/msg/PoseStamped", 10.0),
    Stream("/status", "std_msgs/msg/String", 1.0),
    Stream(CAMERA, "sensor_msgs/msg/Image", 10.0),
)
"""The topics with traffic; the other 95 (``/flood`` one of them) have publishers and no
messages."""

_QUIET_TYPES = ("std_msgs/msg/Float64", "sensor_msgs/msg/BatteryState",
                "diagnostic_msgs/msg/DiagnosticArray", "geometry_msgs/msg/Twist",
                "std_msgs/msg/Bool")
_SERVICE_TYPES = ("std_srvs/srv/Trigger", "std_srvs/srv/SetBool")


def _stamp(msg: Any, now_ns: int) -> None:
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(now_ns, 1_000_000_000)


def _answer(call: Any) -> None:
    call.complete()


def _cancel(goal: Any) -> None:
    goal.finish(GoalStatus.CANCELED)


class _Live:
    """A stream being published: its publisher, message template and next due time."""

    __slots__ = ("due", "msg", "pub", "seq", "stream")

    def __init__(self, stream: Stream, pub: MemoryPublisher, msg: Any, due: float) -> None:
        self.stream = stream
        self.pub = pub
        self.msg = msg
        self.due = due
        self.seq = 0


class SimRobot:
    """One simulated robot: its in-memory graph and the bridge's exporter on it."""

    def __init__(self, name: str, options: ZenohOptions) -> None:
        self.name = name
        self.ros = MemoryRos()
        self.bridge = MemoryGraph(self.ros, "roslibpy_lite_bridge")
        self.nodes = [self.ros.node(f"node_{i:02d}", parameters=(
            {"rate": 10.0 + i, "frame_id": f"link_{i}", "enabled": True}
            if i < PARAM_NODES else None)) for i in range(NODES)]
        self.pubs: dict[str, MemoryPublisher] = {}
        for i, stream in enumerate(STREAMS):
            self._advertise(self.nodes[i], stream.topic, stream.type_name)
        self._advertise(self.nodes[len(STREAMS)], FLOOD, "std_msgs/msg/String")
        for i in range(TOPICS - len(STREAMS) - 1):
            node = self.nodes[i % NODES]
            self._advertise(node, f"/{node.name}/out_{i}", _QUIET_TYPES[i % len(_QUIET_TYPES)])
        for i in range(20 - 3 * PARAM_NODES):
            type_name = _SERVICE_TYPES[i % 2]
            self.nodes[PARAM_NODES + i].serve(f"/{self.nodes[PARAM_NODES + i].name}/srv_{i}",
                                              dynamic.DEFAULT.lookup_service(type_name),
                                              _answer)
        self.nodes[-1].serve_action("/navigate",
                                    dynamic.DEFAULT.lookup_action("test_msgs/action/Fibonacci"),
                                    self._on_goal, _cancel)
        self.exporter = Exporter(self.bridge, name, options, snapshot_interval=SNAPSHOT_INTERVAL)
        self.live: dict[str, _Live] = {}
        self.published: dict[str, int] = {}
        self.flood: tuple[int, float] | None = None
        """(bytes, Hz) of ``/flood`` while told to flood."""

    def _advertise(self, node: MemoryGraph, topic: str, type_name: str) -> None:
        self.pubs[topic] = node.acquire_publisher(
            topic, dynamic.DEFAULT.lookup_message(type_name), False, 10)

    @staticmethod
    def _on_goal(goal: Any) -> None:
        order = int(goal.request.order)
        seq = [0, 1]
        while len(seq) < order:
            seq.append(seq[-1] + seq[-2])
        goal.finish(GoalStatus.SUCCEEDED, goal.served.action_cls.Result(sequence=seq[:order]))

    def start(self) -> None:
        """Dial out (the exporter's own start)."""
        self.exporter.start()

    async def close(self) -> None:
        """Leave Zenoh and the graph."""
        await self.exporter.close()
        for node in [*self.nodes, self.bridge]:
            node.close()

    def watched(self, topic: str) -> bool:
        """Whether a relay watches ``topic`` now (the exporter subscribed it)."""
        return topic in self.bridge.subscriptions

    def tick(self, now: float) -> None:
        """Publish each watched stream that is due (and start or stop streams)."""
        streams = [*STREAMS, *([Stream(FLOOD, "std_msgs/msg/String", self.flood[1])]
                               if self.flood else [])]
        for stream in streams:
            live = self.live.get(stream.topic)
            if not self.watched(stream.topic):
                if live is not None:
                    del self.live[stream.topic]
                continue
            if live is None:
                live = self.live[stream.topic] = _Live(stream, self._publisher(stream),
                                                       self._template(stream), now)
            while live.due <= now:
                live.due += 1.0 / stream.hz
                self._publish(live)
            if now - live.due > 1.0:  # starved of CPU: do not catch up a burst
                live.due = now

    def _publisher(self, stream: Stream) -> MemoryPublisher:
        if stream.topic not in self.pubs:
            self._advertise(self.nodes[0], stream.topic, stream.type_name)
        return self.pubs[stream.topic]

    def _template(self, stream: Stream) -> Any:
        msg: Any = dynamic.DEFAULT.lookup_message(stream.type_name)()
        if stream.topic == CAMERA:
            msg.height, msg.width, msg.encoding, msg.step = 480, 640, "rgb8", 640 * 3
            msg.data = os.urandom(640 * 480 * 3)
        elif stream.topic == FLOOD and self.flood is not None:
            msg.data = "x" * self.flood[0]
        return msg

    def _publish(self, live: _Live) -> None:
        live.seq += 1
        msg = live.msg
        now_ns = time.time_ns()
        if hasattr(msg, "header"):
            _stamp(msg, now_ns)
        if live.stream.topic == POSE:
            msg.pose.position.x = float(live.seq)
        elif live.stream.topic == "/status":
            msg.data = json.dumps({"seq": live.seq, "t": now_ns, "ok": True})
        live.pub.publish(msg)
        self.published[live.stream.topic] = self.published.get(live.stream.topic, 0) + 1


@dataclass
class Fleet:
    """The simulated robots of one process, ticked by one task."""

    options: ZenohOptions
    robots: dict[str, SimRobot] = field(default_factory=dict)
    hz: float = 100.0
    ticks: int = 0

    async def add(self, name: str) -> SimRobot:
        """Start robot ``name``."""
        robot = self.robots[name] = SimRobot(name, self.options)
        robot.start()
        return robot

    async def remove(self, name: str) -> None:
        """Stop robot ``name`` (it leaves Zenoh)."""
        robot = self.robots.pop(name, None)
        if robot is not None:
            await robot.close()

    async def until_holding(self, names: list[str], timeout: float) -> list[str]:
        """Wait until every robot of ``names`` holds its name on Zenoh; those that do not."""
        deadline = time.monotonic() + timeout
        while True:
            missing = [n for n in names if n in self.robots
                       and self.robots[n].exporter.uplink.not_ready() is not None]
            if not missing or time.monotonic() > deadline:
                return missing
            await asyncio.sleep(0.2)

    async def run(self) -> None:
        """Tick every robot ``hz`` times a second, for ever."""
        loop = asyncio.get_running_loop()
        period = 1.0 / self.hz
        nxt = loop.time()
        while True:
            now = loop.time()
            for robot in list(self.robots.values()):
                if robot.bridge.subscriptions:  # a robot nobody watches costs no tick
                    robot.tick(now)
            self.ticks += 1
            nxt = max(nxt + period, loop.time())
            await asyncio.sleep(nxt - loop.time())

    async def command(self, cmd: dict[str, Any]) -> dict[str, Any]:
        """One command: ``join``/``leave`` ``robot``; ``flood`` ``robot`` with ``bytes`` at
        ``hz`` (0: stop); ``stats`` (this process's RSS and CPU, how many robots hold their names
        and since when each has (its uplink's wall-clock ``since``), what each published)."""
        op = cmd.get("cmd")
        if op == "join":
            await self.add(str(cmd["robot"]))
            missing = await self.until_holding([str(cmd["robot"])], float(cmd.get("wait", 30)))
            return {"event": "joined", "robot": cmd["robot"], "ok": not missing}
        if op == "leave":
            await self.remove(str(cmd["robot"]))
            return {"event": "left", "robot": cmd["robot"]}
        if op == "flood":
            robot = self.robots[str(cmd["robot"])]
            hz = float(cmd.get("hz", 0))
            robot.flood = (int(cmd.get("bytes", 1000)), hz) if hz > 0 else None
            robot.live.pop(FLOOD, None)
            return {"event": "flooding", "robot": robot.name, "hz": hz}
        if op == "stats":
            import psutil

            proc = psutil.Process()
            cpu = proc.cpu_times()
            return {"event": "stats", "rss": proc.memory_info().rss,
                    "cpu_s": cpu.user + cpu.system, "robots": len(self.robots),
                    "holding": sum(r.exporter.uplink.not_ready() is None
                                   for r in self.robots.values()),
                    "up_since": [r.exporter.uplink.since for r in self.robots.values()
                                 if r.exporter.uplink.not_ready() is None],
                    "published": {n: r.published for n, r in self.robots.items()
                                  if r.published}}
        return {"event": "error", "error": f"unknown command {op!r}: expected join, leave, "
                "flood or stats"}


async def _serve(args: argparse.Namespace) -> int:
    say = json_lines()
    options = RobotOptions(connect=list(args.connect), lease=args.lease)
    fleet = Fleet(options)
    names = [f"{args.prefix}-{i}" for i in range(args.first, args.first + args.count)]
    for name in names:
        await fleet.add(name)
    ticker = asyncio.create_task(fleet.run())
    missing = await fleet.until_holding(names, args.wait)
    say({"event": "ready", "robots": len(names), "missing": missing})
    loop = asyncio.get_running_loop()
    reader = asyncio.StreamReader()
    await loop.connect_read_pipe(lambda: asyncio.StreamReaderProtocol(reader), sys.stdin)
    try:
        while line := await reader.readline():
            try:
                answer = await fleet.command(json.loads(line))
            except (ValueError, KeyError, TypeError) as exc:
                answer = {"event": "error", "error": f"bad command {line[:100]!r}: {exc}"}
            say(answer)
    finally:
        ticker.cancel()
        for name in list(fleet.robots):
            with contextlib.suppress(Exception):
                await fleet.remove(name)
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run ``--count`` simulated robots until stdin closes (see the module's text)."""
    p = argparse.ArgumentParser(prog="python -m bench.simrobot", description=__doc__)
    p.add_argument("--connect", action="append", required=True, metavar="ENDPOINT",
                   help="a Zenoh router to dial (repeatable)")
    p.add_argument("--count", type=int, default=10, help="robots in this process")
    p.add_argument("--first", type=int, default=0, help="the first robot's number")
    p.add_argument("--prefix", default="sim", help="robots are named PREFIX-<n>")
    p.add_argument("--lease", type=float, default=3.0, help="Zenoh lease, seconds")
    p.add_argument("--wait", type=float, default=120.0,
                   help="seconds to wait for every robot to hold its name")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    return asyncio.run(_serve(args))


if __name__ == "__main__":
    sys.exit(main())
