"""Nothing lost in a robot-link outage, within a bounded window (issue 38, item 4).

Real parts, each its own process: a relay that is the Zenoh router, a robot's bridge
(``--no-websocket``) dialing it through a TCP proxy (:class:`~bench.linkproxy.LinkProxy`,
whose blackhole is a cut cable: no FIN, silence both ways), and an rclpy node publishing a
reliable 10 Hz counter on the robot. The clients of the robot through the relay: our client,
stock roslibpy (its own child process) and the Foxglove npm client (``@foxglove/ws-protocol``
in Node). The link is cut for longer than the Zenoh lease (3 s): the relay tells the clients
the robot went away, the counter goes on in ROS; then the link comes back.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import re
import sys
import textwrap
import urllib.request
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

import roslibpy_lite
from bench.linkproxy import LinkProxy
from rosbridge_core.protocol import ops
from tests.helpers import ros_env
from tests.peers.peer import NODE_DIR, PeerProcess, foxglove_peer
from tests.relay.procs import Proc, until_robot_served
from tests.relay.support import free_port, lone_session, until

pytestmark = pytest.mark.timeout(120)

ROBOT = "outbot"
TOPIC = "/outage/count"
READY = re.compile(r"relay listening on ws://127\.0\.0\.1:(\d+)")

COUNTER = textwrap.dedent("""
    import os
    import sys

    import rclpy
    from rclpy.executors import ExternalShutdownException
    from std_msgs.msg import String

    rclpy.init()
    node = rclpy.create_node("outage_counter")
    pub = node.create_publisher(String, sys.argv[1], 10)  # reliable, volatile: replayed
    n = [0]
    stop = sys.argv[2] if len(sys.argv) > 2 else None  # a file: there, the counter stops

    def tick():
        if stop is not None and os.path.exists(stop):
            if n[0] >= 0:
                print(f"stopped after {n[0]}", flush=True)
                n[0] = -1
            return
        n[0] += 1
        pub.publish(String(data=str(n[0])))
        print(f"sent {n[0]}", flush=True)

    node.create_timer(0.1, tick)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
""")

# Stock roslibpy, unchanged, in a child process; each message it hears is a line.
ROSLIBPY = textwrap.dedent("""
    import json, sys, threading
    import roslibpy

    ros = roslibpy.Ros(host=sys.argv[1])
    ros.run(timeout=30)
    roslibpy.Topic(ros, sys.argv[2], "std_msgs/msg/String", queue_length=1000).subscribe(
        lambda m: print("heard " + m["data"], flush=True))
    print("subscribed", flush=True)
    threading.Event().wait()
""")


@dataclass
class Outage:
    """The relay, the link, the robot's bridge and its counter node."""

    relay: Proc
    link: LinkProxy
    robot: Proc
    counter: Proc
    port: int

    @property
    def url(self) -> str:
        """The robot through the relay."""
        return f"ws://127.0.0.1:{self.port}/{ROBOT}"

    def sent(self) -> int:
        """The counter's last number published in ROS."""
        return max((int(line.split()[1]) for line in list(self.counter.lines)
                    if line.startswith("sent ")), default=0)


@contextlib.contextmanager
def outage_tier(*robot_options: str, stop_file: str | None = None) -> Iterator[Outage]:
    """A relay, a robot's bridge (``robot_options`` added) dialing it through a LinkProxy,
    and the robot's counter node (which stops once ``stop_file`` exists); the robot is
    served by the relay when it yields."""
    zport, port = free_port(), free_port()
    procs: list[Proc] = []
    try:
        procs.append(Proc([sys.executable, "-m", "bridge_server.zenoh.relay", "--port", str(port),
                           "--zenoh-listen", f"tcp/127.0.0.1:{zport}"], ros_env()))
        procs[0].wait_for(READY)
        with LinkProxy(("127.0.0.1", zport)) as link:
            procs.append(Proc([sys.executable, "-m", "bridge_server", "--no-websocket",
                               "--robot", ROBOT, "--zenoh-connect",
                               f"tcp/127.0.0.1:{link.port}", *robot_options], ros_env()))
            procs[1].wait_for(re.compile(rf"robot {ROBOT} is on Zenoh"))
            procs.append(Proc([sys.executable, "-c", COUNTER, TOPIC,
                               *([stop_file] if stop_file else [])], ros_env()))
            procs[2].wait_for(re.compile("sent 1$"))
            until_robot_served(port, ROBOT)
            yield Outage(procs[0], link, procs[1], procs[2], port)
    finally:
        for p in reversed(procs):
            p.stop()


def heard_by_roslibpy(proc: Proc) -> list[int]:
    """The numbers stock roslibpy heard, in order."""
    return [int(line.split()[1]) for line in list(proc.lines) if line.startswith("heard ")]


def heard_by_foxglove(fox: PeerProcess) -> list[int]:
    """The numbers the Foxglove client heard, in order."""
    return [int(e["msg"]["data"]) for e in fox.new_events()
            if e.get("event") == "message" and e.get("topic") == TOPIC]


def _foxglove() -> bool:
    return (NODE_DIR / "node_modules" / "@foxglove" / "ws-protocol").is_dir()


@contextlib.contextmanager
def explained(t: Outage, heard: dict[str, Callable[[], list[int]]],
              statuses: list[ops.Status]) -> Iterator[None]:
    """A failure inside says what each client heard last, our client's statuses, what the
    counter sent and the relay's and the robot's logs."""
    try:
        yield
    except AssertionError as exc:
        said = [f"{name} heard (last 15): {h()[-15:]}" for name, h in heard.items()]
        said += [f"our client's statuses: {[(s.level, s.msg) for s in statuses]}",
                 f"counter sent up to {t.sent()}"]
        for name, proc in (("relay", t.relay), ("robot", t.robot)):
            said += [f"--- {name}'s log (last 40 lines):", *list(proc.lines)[-40:]]
        raise AssertionError(f"{exc}\n" + "\n".join(said)) from None


@contextlib.asynccontextmanager
async def clients(t: Outage) -> Any:
    """Our client, stock roslibpy and (where npm's packages are) the Foxglove client, each
    subscribed to the counter and hearing it; yields the three ways to read what each heard
    and our client's statuses (a failure meanwhile is :func:`explained`)."""
    ours: list[int] = []
    statuses: list[ops.Status] = []
    stock = Proc([sys.executable, "-c", ROSLIBPY, t.url, TOPIC], ros_env())
    fox = foxglove_peer(t.url) if _foxglove() else None
    try:
        async with roslibpy_lite.connect(t.url) as ros:
            ros.on_status(statuses.append)
            ros.subscribe(TOPIC, "std_msgs/msg/String", lambda m: ours.append(int(m["data"])),
                          queue_length=1000)
            if fox is not None:
                await asyncio.to_thread(fox.request, "subscribe", topic=TOPIC,
                                        timeout_ms=30000, timeout=35)
            heard: dict[str, Callable[[], list[int]]] = {
                "roslibpy_lite": lambda: ours, "roslibpy": lambda: heard_by_roslibpy(stock)}
            if fox is not None:
                heard["foxglove"] = lambda: heard_by_foxglove(fox)
            await until(lambda: all(h() for h in heard.values()), "every client to hear "
                        "the counter", 30)
            with explained(t, heard, statuses):
                yield heard, statuses, fox
    finally:
        stock.stop()
        if fox is not None:
            fox.close()


async def _cut(t: Outage, statuses: list[ops.Status], published: int,
               stop: Path | None = None) -> tuple[int, int]:
    """Blackhole the robot's link until the relay told our client the robot went away (its
    lease ran out) and the counter published ``published`` more; restore it. Given ``stop``,
    the counter is stopped once it published ``published`` more in the cut, before the lease
    ran out: the topic is then silent in the cut for most of the lease (3 s), longer than the
    robot's heartbeat period (1 s). Returns the counter's last number before the cut and at
    the restore."""
    before = t.sent()
    t.link.blackhole()
    try:
        if stop is not None:
            await until(lambda: t.sent() >= before + published, "the counter to go on", 20)
            stop.touch()
            await until(lambda: any(line.startswith("stopped") for line in t.counter.lines),
                        "the counter to stop", 10)
        await until(lambda: any("went away" in s.msg for s in statuses),
                    "the relay to tell our client the robot went away", 20)
        if stop is None:
            gone = t.sent()
            await until(lambda: t.sent() >= gone + published, "the counter to go on", 20)
    finally:
        t.link.restore()
    return before, t.sent()


def _gaps(numbers: list[int]) -> list[tuple[int, int]]:
    """(after, missing) for each place where ``numbers`` skips."""
    return [(a, b - a - 1) for a, b in itertools.pairwise(numbers) if b != a + 1]


async def test_a_cut_longer_than_the_lease_loses_nothing() -> None:
    """A reliable 10 Hz counter, the robot's link cut past the lease (3 s) for about 5 s:
    every number published meanwhile reaches our client, stock roslibpy and the Foxglove
    client once and in order when the link is back."""
    with outage_tier() as t:
        async with clients(t) as (heard, statuses, _fox):
            before, restored = await _cut(t, statuses, published=20)
            await until(lambda: all(h() and h()[-1] >= restored + 10 for h in heard.values()),
                        "every client to hear the counter after the cut", 30)
            for name, h in heard.items():
                numbers = h()
                assert _gaps(numbers) == [] and len(set(numbers)) == len(numbers), (
                    name, numbers)
                assert numbers[0] <= before, (name, numbers[:5], before)


async def test_what_a_topic_said_last_in_an_outage_arrives_though_it_fell_silent(
        tmp_path: Path) -> None:
    """The counter stops early in the cut, silent for longer than a heartbeat period before
    the link is back: nothing after the gap shows it, yet its last numbers reach every
    client once the link is back (the robot's heartbeat, sent each period whether or not
    the topic published, tells the relay what it missed)."""
    stop = tmp_path / "stop"
    with outage_tier(stop_file=str(stop)) as t:
        async with clients(t) as (heard, statuses, _fox):
            _before, last = await _cut(t, statuses, published=5, stop=stop)
            await until(lambda: all(h()[-1] == last for h in heard.values()),
                        f"every client to hear the counter's last number, {last}", 30)
            for name, h in heard.items():
                numbers = h()
                assert _gaps(numbers) == [] and len(set(numbers)) == len(numbers), (
                    name, numbers)


async def test_a_cut_beyond_the_window_tells_how_many_were_lost() -> None:
    """With a window of 20 messages, a cut of about 5 s at 10 Hz loses the oldest: our
    client and the Foxglove client get a warning naming the topic and the count, which is
    the one gap in the numbers heard; the window's last 20 still arrive, in order."""
    with outage_tier("--relay-replay-count", "20") as t:
        async with clients(t) as (heard, statuses, fox):
            before, restored = await _cut(t, statuses, published=20)
            told = await until(lambda: [s for s in statuses if " were lost" in s.msg],
                               "a status about the lost messages", 30)
            assert told[0].level == "warning" and TOPIC in told[0].msg, told
            lost = int(re.search(r"(\d+) messages of " + re.escape(TOPIC) + " were lost",
                                 told[0].msg)[1])  # type: ignore[index]
            assert lost >= restored - before - 20, (lost, before, restored, told[0].msg)
            await until(lambda: all(h() and h()[-1] >= restored + 10 for h in heard.values()),
                        "every client to hear the counter after the cut", 30)
            for name, h in heard.items():
                numbers = h()
                gaps = _gaps(numbers)
                assert len(gaps) == 1 and gaps[0][1] == lost, (name, gaps, lost)
                assert len(set(numbers)) == len(numbers), name
            relay_metrics = f"http://127.0.0.1:{t.port}/metrics"
            assert _metric(relay_metrics, "roslibpy_relay_robot_dropped_total", robot=ROBOT,
                           kind="messages_lost") == lost
            if fox is not None:
                said = [e for e in fox.new_events() if e.get("event") == "status"
                        and " were lost" in e.get("message", "")]
                assert said and f"{lost} messages" in said[0]["message"], json.dumps(said)


def _metric(url: str, name: str, **labels: str) -> float | None:
    """The value of ``name{labels}`` at the ``/metrics`` ``url`` (``None``: not there)."""
    with urllib.request.urlopen(url, timeout=10) as reply:
        text = reply.read().decode()
    for line in text.splitlines():
        series, _, value = line.rpartition(" ")
        head, _, rest = series.partition("{")
        if head == name and all(f'{k}="{v}"' in rest for k, v in labels.items()):
            return float(value)
    return None


@pytest.mark.parametrize("option", ["--relay-replay-bytes", "--relay-replay-total-bytes"])
async def test_the_window_is_bounded_in_bytes_and_shown_in_metrics(option: str) -> None:
    """A byte cap of 60 bytes, the topic's or all topics' (a counter's message is 12 to 13
    bytes of CDR), bounds the window to what fits, however many messages it may hold: the
    robot's /metrics (on ``--metrics-port``: it has no websocket listener) shows its
    messages and bytes, at most the cap."""
    mport = free_port()
    with outage_tier(option, "60", "--metrics-port", str(mport)) as t:
        async with clients(t):
            robot = f"http://127.0.0.1:{mport}/metrics"
            topic = {"topic": TOPIC}
            # the window fills up (no event: the robot's counter runs at 10 Hz)
            await until(lambda: (_metric(robot, "roslibpy_bridge_relay_replay_messages",
                                         **topic) or 0) >= 4, "the window to fill", 20)
            start = t.sent()
            await until(lambda: t.sent() >= start + 10, "ten more messages", 20)
            held = _metric(robot, "roslibpy_bridge_relay_replay_messages", **topic)
            held_bytes = _metric(robot, "roslibpy_bridge_relay_replay_bytes", **topic)
            assert held is not None and held_bytes is not None
            assert 4 <= held <= 5 and 12 * held <= held_bytes <= 60, (held, held_bytes)


@pytest.mark.parametrize(("option", "value", "said"), [
    ("--relay-replay-count", "-1", "--relay-replay-count -1: expected 0 or more messages"),
    ("--relay-replay-bytes", "0", "--relay-replay-bytes 0: expected 1 or more bytes"),
    ("--relay-replay-total-bytes", "0", "--relay-replay-total-bytes 0: expected 1 or more "
     "bytes")])
def test_a_window_that_cannot_be_is_refused_naming_its_option(option: str, value: str,
                                                               said: str) -> None:
    """A robot's bridge given a negative replay count or no bytes refuses to start (status
    2), naming the option and what it takes."""
    import subprocess

    done = subprocess.run([sys.executable, "-m", "bridge_server", "--no-websocket", "--robot",
                           ROBOT, "--zenoh-connect", "tcp/127.0.0.1:7447", option, value],
                          env=ros_env(), capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and said in done.stderr, done.stderr


def test_the_robots_windows_share_one_budget() -> None:
    """Windows reserve their depth times their largest message from the robot's total: a
    topic with no room left is put plainly (not replayed), and a closed window's room goes
    to the next (a real Zenoh session, alone: no scouting, no endpoints)."""
    from bridge_server.zenoh.replay import ReplayBudget, ReplayPublisher, ReplayWindow

    with lone_session() as session:
        window = ReplayWindow(count=300, bytes=1000, total=100)
        budget = ReplayBudget(window.total)
        a = ReplayPublisher(session, "r/a", window, "/a", budget)
        b = ReplayPublisher(session, "r/b", window, "/b", budget)
        for _ in range(5):
            a.put(b"x" * 30, b"{}")
            b.put(b"y" * 20, b"{}")
        assert (a.held, a.held_bytes, a.plain) == (3, 90, False)  # 100 // 30
        assert (b.held, b.plain, budget.reserved) == (0, True, 90)  # 10 left: not one
        a.close()
        assert budget.reserved == 0
        c = ReplayPublisher(session, "r/c", window, "/c", budget)
        for _ in range(7):
            c.put(b"z" * 20, b"{}")
        assert (c.held, c.held_bytes, budget.reserved) == (5, 100, 100)
        c.put(b"z" * 40, b"{}")  # larger: a shallower window, what it held dropped
        assert (c.held, c.held_bytes, c.resized, budget.reserved) == (1, 40, 1, 80)
        c.close()
        b.close()


def test_a_topic_of_big_messages_is_put_plainly() -> None:
    """A topic whose message is over REPLAY_MAX_MESSAGE_BYTES is put plainly from then on
    (latest wins): its cache goes and gives its room back, and it does not come back for
    smaller messages after; a topic that starts big never caches (a real Zenoh session,
    alone)."""
    from bridge_server.zenoh.replay import (
        REPLAY_MAX_MESSAGE_BYTES,
        ReplayBudget,
        ReplayPublisher,
        ReplayWindow,
    )

    with lone_session() as session:
        window = ReplayWindow()
        budget = ReplayBudget(window.total)
        odom = ReplayPublisher(session, "r/odom", window, "/odom", budget)
        for _ in range(3):
            odom.put(b"o" * 1024, b"{}")
        assert (odom.held, odom.plain) == (3, False) and budget.reserved > 0
        odom.put(b"O" * (REPLAY_MAX_MESSAGE_BYTES + 1), b"{}")
        assert (odom.held, odom.held_bytes, odom.plain, budget.reserved) == (0, 0, True, 0)
        odom.put(b"o" * 1024, b"{}")
        assert (odom.held, odom.plain) == (0, True)
        camera = ReplayPublisher(session, "r/camera", window, "/camera", budget)
        camera.put(b"c" * (640 * 480 * 3), b"{}")
        assert (camera.held, camera.plain, budget.reserved) == (0, True, 0)
        edge = ReplayPublisher(session, "r/edge", window, "/edge", budget)
        edge.put(b"e" * REPLAY_MAX_MESSAGE_BYTES, b"{}")  # the largest that is replayed
        assert (edge.held, edge.plain) == (1, False)
        for pub in (odom, camera, edge):
            pub.close()


async def test_a_replayed_topic_is_let_go_once_the_link_is_back_and_nobody_asks(
        ros_node: Any, topic: str) -> None:
    """The robot keeps a replayed topic subscribed, and caching, while its link is down
    (its relays cannot say whether they still watch), past the linger; once the link is
    back and no relay asks for the topic for the linger, it unsubscribes (an in-process
    tier: a relay that is the router, stopped and started again without clients)."""
    from std_msgs.msg import String

    from tests.relay.support import ROBOT as ROBOT1
    from tests.relay.support import robot_reachable, start_relay, start_robot

    pub = ros_node.create_publisher(String, topic, 10)
    router = f"tcp/127.0.0.1:{free_port()}"
    relay = await start_relay(listen=router)
    robot, exporter = await start_robot(router)
    exporter.demand_linger = 0.5
    try:
        await robot_reachable(relay)
        async with roslibpy_lite.connect(f"ws://127.0.0.1:{relay.port}/{ROBOT1}") as ros:
            sub = ros.subscribe(topic, "std_msgs/msg/String")
            while True:  # the robot's subscription matches the publisher in its own time
                pub.publish(String(data="kept"))
                with contextlib.suppress(TimeoutError):
                    await sub.get(0.2)
                    break
            await relay.close()  # the link goes with the router
            await until(lambda: exporter.uplink_lost == 1, "the robot to see its uplink go")
        export = exporter.exports[topic]
        assert export.replay is not None
        held = export.replay.held
        for _ in range(4):  # four lingers with the link down: kept, and caching
            await asyncio.sleep(exporter.demand_linger)
            pub.publish(String(data="while the link is down"))
        await until(lambda: export.replay is not None and export.replay.held > held,
                    "the window to take what is published while the link is down")
        assert exporter.exports.get(topic) is export and not export.relays
        relay = await start_relay(listen=router)  # back, and nobody asks for the topic
        await until(lambda: exporter.uplinks, "the robot to dial its router again", 30)
        await until(lambda: topic not in exporter.exports, "the topic to be let go", 10)
    finally:
        await relay.close()
        await exporter.close()
        await robot.close()
