"""A robot nobody can reach, reached through two relays (issue 26).

The robot's bridge and its rclpy node run in a network namespace this test makes: inside
it, only loopback and one veth link whose far end (in this namespace, on an address the
test gives it) is the Zenoh router of the first relay. Nothing listens inside the robot's
namespace, so nothing can connect in; the bridge dials out. A second relay, here, is a
Zenoh client of that router. One set-up serves the module: clients connect to either relay
on 127.0.0.1 and name the robot in the URL path. Our client, stock roslibpy and stock
roslib in headless Chromium hear the robot's topics (latched too, and a type only the
robot has), publish to it, call its service and its action (of its own type), serve a
service and an action its node calls, and ``bag record`` records it. Then the robot's link
is cut and the router restarted (these two last: they disturb the tier).

Needs root and ``ip`` (iproute2), and Chromium for the browser; under CI (``CI=true``)
their absence fails the run (tests/conftest.py), here it skips.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import re
import shutil
import socket
import subprocess
import sys
import textwrap
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from websockets.asyncio.client import connect as ws_connect
from websockets.exceptions import InvalidStatus

import roslibpy_lite
from roslibpy_lite.actions import GoalContext, GoalStatus
from roslibpy_lite.bag import info, read
from roslibpy_lite.handles import Publisher, Subscription
from tests.helpers import (
    CHROMEDRIVER,
    CHROMIUM,
    ROOT,
    WireClient,
    free_port,
    open_wire,
    ros_env,
)
from tests.relay.procs import Proc, until_robot_served
from tests.relay.test_browser import NODE_MODULES, heard_and_answered, roslib_in_chromium

ROBOT = "natbot"
READY = re.compile(r"relay listening on ws://127\.0\.0\.1:(\d+)")

# The robot's own ROS side, all in the robot's namespace: a talker, an echo of what the
# relays' clients publish, a latched topic said once, a topic of its own type, a service,
# an action of a type msgs does not generate, and a client and an action client that call
# what the relays' clients serve as soon as it is there, telling each answer on /nat/answered.
ROBOT_NODE = textwrap.dedent("""
    import rclpy, sys
    from rclpy.action import ActionClient, ActionServer
    from rclpy.executors import ExternalShutdownException
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from example_interfaces.action import Fibonacci
    from robot_msgs.msg import Status, Wheel
    from std_msgs.msg import String
    from std_srvs.srv import SetBool
    from test_msgs.action import Fibonacci as TestFibonacci

    rclpy.init()
    node = rclpy.create_node("nat_robot")
    talk = node.create_publisher(String, "/nat/chatter", 10)
    echo = node.create_publisher(String, "/nat/echo", 10)
    node.create_subscription(String, "/nat/cmd", lambda m: echo.publish(String(data="echo " + m.data)), 10)
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    node.create_publisher(String, "/nat/latched", latched).publish(String(data="said once"))
    status = node.create_publisher(Status, "/nat/status", 10)

    def serve(request, response):
        response.success = request.data
        response.message = "answered inside the namespace"
        return response

    node.create_service(SetBool, "/nat/set", serve)

    def fibonacci(handle):
        sequence = [0, 1]
        for _ in range(1, handle.request.order):
            handle.publish_feedback(Fibonacci.Feedback(sequence=sequence))
            sequence.append(sequence[-1] + sequence[-2])
        handle.succeed()
        return Fibonacci.Result(sequence=sequence)

    ActionServer(node, Fibonacci, "/nat/fib", fibonacci)

    # What the relays' clients serve, called from inside: each answer is told on /nat/answered.
    answered = node.create_publisher(String, "/nat/answered", 10)
    asks = node.create_client(SetBool, "/nat/served")
    goals = ActionClient(node, TestFibonacci, "/nat/served_fib")
    pending = {"service": False, "action": False}

    def told(what, text):
        pending[what] = False
        answered.publish(String(data=text))

    def ask():
        if not pending["service"] and asks.service_is_ready():
            pending["service"] = True
            asks.call_async(SetBool.Request(data=True)).add_done_callback(
                lambda f: told("service", f"service {f.result().success} {f.result().message}"))
        if not pending["action"] and goals.server_is_ready():
            pending["action"] = True

            def accepted(f):
                f.result().get_result_async().add_done_callback(lambda r: told(
                    "action", f"action {r.result().status} {list(r.result().result.sequence)}"))

            goals.send_goal_async(
                TestFibonacci.Goal(order=4), feedback_callback=lambda m: answered.publish(
                    String(data=f"feedback {list(m.feedback.sequence)}")),
            ).add_done_callback(accepted)

    node.create_timer(0.1, ask)
    count = [0]

    def tick():
        count[0] += 1
        talk.publish(String(data=f"hello {count[0]}"))
        status.publish(Status(mode=Status.MODE_DRIVE, label="natbot", blob=b"\\x07",
                              battery_cells=[3.5, 3.75],
                              wheels=[Wheel(name="left", speed=0.5, ticks=[count[0], 0, 0])]))

    node.create_timer(0.05, tick)
    print("robot node up", flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
""")


@dataclass
class Namespace:
    """The robot's network namespace and the veth pair to the router's side."""

    name: str
    router_ip: str
    robot_ip: str
    host_end: str
    """The veth's end on this side: set down, it cuts the robot off (a blackhole)."""

    def exec(self, *argv: str) -> list[str]:
        """``argv`` to run inside the namespace."""
        return ["ip", "netns", "exec", self.name, *argv]


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True)


def _free_subnet(first: int) -> str:
    """``10.213.N`` for the first ``N`` from ``first`` that no interface here has: a veth
    another run left behind with the same address would take the robot's traffic (it did,
    with pids 200 apart), and the robot would reach no router."""
    used = subprocess.run(["ip", "-br", "addr"], check=True, capture_output=True,
                          text=True).stdout
    for k in range(200):
        subnet = f"10.213.{(first + k) % 200}"
        if f" {subnet}." not in used:
            return subnet
    raise RuntimeError("every 10.213.N/30 here is taken: old test namespaces left behind "
                       "('ip netns list')")


@pytest.fixture(scope="module")
def robot_netns() -> Iterator[Namespace]:
    """A namespace with only loopback and a /30 veth link to this namespace."""
    if os.geteuid() != 0 or shutil.which("ip") is None:
        pytest.skip("network namespaces need root and iproute2 ('ip')")
    tag = f"{os.getpid() % 10000}"
    host_end, robot_end = f"rlh{tag}", f"rlr{tag}"
    subnet = _free_subnet(os.getpid() % 200)
    ns = Namespace(f"rlnat{tag}", f"{subnet}.1", f"{subnet}.2", host_end)
    _ip("netns", "add", ns.name)
    try:
        _ip("link", "add", host_end, "type", "veth", "peer", "name", robot_end)
        _ip("link", "set", robot_end, "netns", ns.name)
        _ip("addr", "add", f"{ns.router_ip}/30", "dev", host_end)
        _ip("link", "set", host_end, "up")
        _ip("netns", "exec", ns.name, "ip", "addr", "add", f"{ns.robot_ip}/30", "dev", robot_end)
        _ip("netns", "exec", ns.name, "ip", "link", "set", robot_end, "up")
        _ip("netns", "exec", ns.name, "ip", "link", "set", "lo", "up")
        yield ns
    finally:
        with contextlib.suppress(subprocess.CalledProcessError):
            _ip("link", "del", host_end)  # takes its peer with it
        _ip("netns", "del", ns.name)


@dataclass
class Fleet:
    """The fleet's certificates, made by ``roslibpy-lite-relay certs`` as the relay guide's
    quick start makes them: relay1 (the router), relay2 (a client of it) and the robot."""

    dir: Path

    @classmethod
    def make(cls, folder: Path, router_ip: str) -> Fleet:
        """Run the command (the relays named by the router's address on the veth)."""
        done = subprocess.run(
            [sys.executable, "-m", "bridge_server.zenoh.relay", "certs", "--dir", str(folder),
             "--relay", "relay1", "--relay", "relay2", "--relay-host", router_ip,
             "--robot", ROBOT], cwd=ROOT, env=ros_env(), capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
        return cls(folder)

    def tls(self, name: str) -> list[str]:
        """The Zenoh TLS options of ``name`` (a relay or the robot)."""
        return ["--zenoh-tls-ca", str(self.dir / "ca.pem"),
                "--zenoh-tls-cert", str(self.dir / f"{name}.pem"),
                "--zenoh-tls-key", str(self.dir / f"{name}.key")]

    def router(self) -> list[str]:
        """relay1 as the router: it asks for certificates, lets in the robot and relay2."""
        return [*self.tls("relay1"), "--zenoh-mtls", "--zenoh-robot", ROBOT,
                "--zenoh-relay", "relay2"]


def start_relay(port: int, zenoh: str, endpoint: str, tls: list[str]) -> Proc:
    """A relay serving websockets on ``port``; ``zenoh`` is ``--zenoh-listen`` (the router)
    or ``--zenoh-connect`` (a client of it), at ``endpoint``, with the ``tls`` options."""
    relay = Proc([sys.executable, "-m", "bridge_server.zenoh.relay", "--port", str(port),
                  zenoh, endpoint, *tls], ros_env())
    relay.wait_for(READY)
    return relay


NODE_OFFERS = ({"/nat/chatter", "/nat/latched", "/nat/status"}, {"/nat/set"}, {"/nat/fib"})
"""The robot node's topics, services and actions the tests use."""


async def _lists_the_robots_node(url: str, timeout: float = 30.0) -> None:
    """Wait until the relay at ``url`` lists what the robot's node offers (ROS discovery on
    the robot, then its graph snapshot over Zenoh: no event here)."""
    async with roslibpy_lite.connect(url) as ros:
        deadline = asyncio.get_running_loop().time() + timeout
        while True:
            listed = ({t.name for t in await ros.graph.topics()},
                      {s.name for s in await ros.graph.services()},
                      {a.name for a in await ros.graph.actions()})
            if all(want <= have for want, have in zip(NODE_OFFERS, listed, strict=True)):
                return
            assert asyncio.get_running_loop().time() < deadline, listed
            await asyncio.sleep(0.2)


@dataclass
class Tier:
    """The two relays, the robot's bridge and node, and where clients connect."""

    ns: Namespace
    fleet: Fleet
    router: Proc
    """The first relay, also the Zenoh router on the veth's address."""
    second: Proc
    """The second relay, here (outside the namespace), a Zenoh client of the first."""
    robot: Proc
    node: Proc
    zport: int
    port: int
    second_port: int

    @property
    def endpoint(self) -> str:
        """The router's Zenoh endpoint, the only address the robot can reach."""
        return f"tls/{self.ns.router_ip}:{self.zport}"

    @property
    def url(self) -> str:
        """The robot through the first relay."""
        return f"ws://127.0.0.1:{self.port}/{ROBOT}"

    @property
    def second_url(self) -> str:
        """The robot through the second relay."""
        return f"ws://127.0.0.1:{self.second_port}/{ROBOT}"

    def restart_router(self) -> None:
        """Stop the first relay (the Zenoh router) and start it again on the same ports."""
        self.router.stop()
        self.router = start_relay(self.port, "--zenoh-listen", self.endpoint,
                                  self.fleet.router())

    def stop(self) -> None:
        """Every process, the clients of the router first."""
        for p in (self.node, self.robot, self.second, self.router):
            p.stop()


@pytest.fixture(scope="module")
def relay_and_robot(robot_netns: Namespace, tmp_path_factory: pytest.TempPathFactory
                    ) -> Iterator[Tier]:
    """The router relay here on the veth's address, a second relay here dialing it, the
    robot's bridge and node in the namespace, every Zenoh link mutual TLS with certificates
    from ``roslibpy-lite-relay certs``; both relays have the robot when it yields."""
    zport, port, second_port = free_port(), free_port(), free_port()
    fleet = Fleet.make(tmp_path_factory.mktemp("fleet") / "certs", robot_netns.router_ip)
    endpoint = f"tls/{robot_netns.router_ip}:{zport}"
    procs: list[Proc] = []
    try:
        procs.append(start_relay(port, "--zenoh-listen", endpoint, fleet.router()))
        procs.append(start_relay(second_port, "--zenoh-connect", endpoint, fleet.tls("relay2")))
        robot = Proc(robot_netns.exec(sys.executable, "-m", "bridge_server", "--no-websocket",
                                      "--robot", ROBOT, "--zenoh-connect", endpoint,
                                      *fleet.tls(ROBOT)), ros_env())
        procs.append(robot)
        robot.wait_for(re.compile(rf"robot {ROBOT} is on Zenoh"))
        node = Proc(robot_netns.exec(sys.executable, "-c", ROBOT_NODE), ros_env())
        procs.append(node)
        node.wait_for(re.compile("robot node up"))
        until_robot_served(port, ROBOT)
        until_robot_served(second_port, ROBOT)
        t = Tier(robot_netns, fleet, procs[0], procs[1], robot, node, zport, port, second_port)
        for url in (t.url, t.second_url):
            asyncio.run(_lists_the_robots_node(url))
        procs = []  # the tier's now: a restarted router is only there
        try:
            yield t
        finally:
            t.stop()
    finally:
        for p in reversed(procs):
            p.stop()


def test_nothing_can_connect_to_the_robot(relay_and_robot: Tier) -> None:
    """The robot's namespace listens on no TCP port; its bridge's port is closed from outside."""
    ns = relay_and_robot.ns
    listening = subprocess.run(ns.exec("ss", "-ltnH"), capture_output=True, text=True,
                               check=True).stdout.strip()
    assert listening == ""
    with socket.socket() as s, pytest.raises(ConnectionRefusedError):
        s.settimeout(5)
        s.connect((ns.robot_ip, 9090))


async def _publish_until_heard(pub: Publisher[Any], text: str, *subs: Subscription[dict[str, Any]],
                               expect: str) -> None:
    """Publish ``text`` until each of ``subs`` heard ``expect`` (the robot's subscriber matches
    a new publisher in its own time)."""
    heard = [False] * len(subs)
    deadline = asyncio.get_running_loop().time() + 30
    while not all(heard):
        await pub.publish({"data": text})
        for i, sub in enumerate(subs):
            with contextlib.suppress(TimeoutError):
                while not heard[i]:
                    heard[i] = (await sub.get(0.3))["data"] == expect
        assert asyncio.get_running_loop().time() < deadline, f"{expect!r} heard by {heard}"


async def test_a_client_reaches_the_robot_through_the_relay(relay_and_robot: Tier) -> None:
    """Our client on the router's relay hears the robot's topic, calls its service and
    publishes to it."""
    async with roslibpy_lite.connect(relay_and_robot.url) as ros:
        sub = ros.subscribe("/nat/chatter", "std_msgs/msg/String")
        first = await sub.get(30)
        assert first["data"].startswith("hello ")
        answer = await ros.call_service("/nat/set", "std_srvs/srv/SetBool", {"data": True},
                                        timeout=30)
        assert answer == {"success": True, "message": "answered inside the namespace"}
        echoes = ros.subscribe("/nat/echo", "std_msgs/msg/String")
        pub = await ros.advertise("/nat/cmd", "std_msgs/msg/String")
        await _publish_until_heard(pub, "from outside", echoes, expect="echo from outside")


async def test_clients_of_both_relays(relay_and_robot: Tier) -> None:
    """A client of the second relay (a Zenoh client of the router, outside the namespace)
    publishes to the robot, and the robot's answer and its own topic reach clients of both
    relays."""
    t = relay_and_robot
    async with roslibpy_lite.connect(t.url) as one, roslibpy_lite.connect(t.second_url) as two:
        for ros in (one, two):
            chatter = ros.subscribe("/nat/chatter", "std_msgs/msg/String")
            assert (await chatter.get(30))["data"].startswith("hello ")
        echoes = [ros.subscribe("/nat/echo", "std_msgs/msg/String") for ros in (one, two)]
        pub = await two.advertise("/nat/cmd", "std_msgs/msg/String")
        await _publish_until_heard(pub, "from relay two", *echoes, expect="echo from relay two")


async def test_latched_and_the_robots_own_type(relay_and_robot: Tier) -> None:
    """The robot's latched topic, said once when its node started, reaches a client of each
    relay that subscribes long after; a message of a type only the robot has (robot_msgs)
    arrives decoded by the relay from the robot's definition."""
    t = relay_and_robot
    async with roslibpy_lite.connect(t.url) as one, roslibpy_lite.connect(t.second_url) as two:
        for ros in (one, two):
            latched = ros.subscribe("/nat/latched", "std_msgs/msg/String")
            assert (await latched.get(30))["data"] == "said once"
        status = await two.subscribe("/nat/status", "robot_msgs/msg/Status").get(30)
        assert status["label"] == "natbot" and status["mode"] == 1
        assert status["battery_cells"] == [3.5, 3.75]
        wheel = status["wheels"][0]
        assert wheel["name"] == "left" and wheel["speed"] == 0.5 and len(wheel["ticks"]) == 3


async def test_an_action_of_the_robots_own_type(relay_and_robot: Tier) -> None:
    """A goal from a client of the second relay runs on the robot's action server
    (example_interfaces, which msgs does not generate): feedback, then the result."""
    async with roslibpy_lite.connect(relay_and_robot.second_url) as ros:
        goal = await ros.send_goal("/nat/fib", "example_interfaces/action/Fibonacci",
                                   {"order": 5})
        feedback = [fb["sequence"] async for fb in goal]
        outcome = await goal.result(timeout=30)
        assert outcome.status is GoalStatus.SUCCEEDED
        assert outcome.values == {"sequence": [0, 1, 1, 2, 3, 5]}
        assert feedback and feedback[0] == [0, 1]


async def test_the_robot_calls_what_relay_clients_serve(relay_and_robot: Tier) -> None:
    """A service served by a client of the first relay and an action served by a client of
    the second are served in ROS on the robot: its node's service and action clients call
    them and get the answer, the feedback and the result (told on /nat/answered)."""
    t = relay_and_robot

    def answer(request: dict[str, Any]) -> dict[str, Any]:
        return {"success": not request["data"], "message": "served through relay one"}

    async def count(goal: dict[str, Any], ctx: GoalContext) -> dict[str, Any]:
        ctx.publish_feedback({"sequence": [0, 1]})
        return {"sequence": [0, 1, 1, 2, 3][:goal["order"] + 1]}

    async with roslibpy_lite.connect(t.url) as one, roslibpy_lite.connect(t.second_url) as two:
        told = one.subscribe("/nat/answered", "std_msgs/msg/String")
        await one.advertise_service("/nat/served", "std_srvs/srv/SetBool", answer)
        await two.advertise_action("/nat/served_fib", "test_msgs/action/Fibonacci", count)
        wanted = {"service False served through relay one", "feedback [0, 1]",
                  "action 4 [0, 1, 1, 2, 3]"}
        heard: set[str] = set()
        deadline = asyncio.get_running_loop().time() + 30
        while not wanted <= heard:
            with contextlib.suppress(TimeoutError):
                heard.add((await told.get(0.5))["data"])
            assert asyncio.get_running_loop().time() < deadline, f"told only {heard}"


# Stock roslibpy, unchanged, in a child process (Twisted's reactor runs once per process);
# the robot is named in the URL's path, which roslibpy takes whole as its host.
ROSLIBPY_SCRIPT = textwrap.dedent("""
    import json, sys, threading
    import roslibpy

    ros = roslibpy.Ros(host=sys.argv[1])
    ros.run(timeout=30)
    heard, got = threading.Event(), []
    roslibpy.Topic(ros, "/nat/chatter", "std_msgs/msg/String").subscribe(
        lambda m: (got.append(m), heard.set()))
    heard.wait(30)
    answer = roslibpy.Service(ros, "/nat/set", "std_srvs/srv/SetBool").call(
        roslibpy.ServiceRequest({"data": False}), timeout=30)
    print(json.dumps({"heard": got[:1], "answer": dict(answer)}), flush=True)
    ros.terminate()
""")


def test_stock_roslibpy_reaches_the_robot(relay_and_robot: Tier) -> None:
    """roslibpy from PyPI, unchanged, on the second relay: the robot's topic and service."""
    done = subprocess.run([sys.executable, "-c", ROSLIBPY_SCRIPT, relay_and_robot.second_url],
                          cwd=ROOT, env=ros_env(), capture_output=True, text=True, timeout=90)
    assert done.returncode == 0, done.stdout + done.stderr
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert result["heard"] and result["heard"][0]["data"].startswith("hello ")
    assert result["answer"] == {"success": False, "message": "answered inside the namespace"}


async def test_roslib_in_chromium_through_the_second_relay(relay_and_robot: Tier) -> None:
    """Stock roslib in headless Chromium (tests/relay/test_browser.py's page) on the second
    relay hears the robot's topic and calls its service."""
    if CHROMIUM is None or CHROMEDRIVER is None or not (NODE_MODULES / "roslib").is_dir():
        pytest.skip("chromium, chromium-driver and the npm peer packages are needed "
                    "(scripts/setup.sh installs them)")
    async with roslib_in_chromium(relay_and_robot.second_url, "/nat/chatter", "/nat/set") as page:
        state = await heard_and_answered(page)
    assert state["got"][0].startswith("hello ")
    assert state["answer"] == {"success": True, "message": "answered inside the namespace"}


async def test_bag_record_through_the_second_relay(relay_and_robot: Tier, tmp_path: Path) -> None:
    """``roslibpy-lite bag record`` on the second relay records the robot's topic: its 20
    messages in order, none lost or twice, with the type's schema."""
    path = tmp_path / "natbot.mcap"
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "roslibpy_lite.cli", "bag", "record", "/nat/chatter",
        "-o", str(path), "--max", "20", "-q", "--url", relay_and_robot.second_url,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE)
    out, err = await asyncio.wait_for(proc.communicate(), 60)
    assert proc.returncode == 0, (out, err)
    about = info(path)
    assert about.complete and about.messages == 20
    assert [(t.topic, t.type_name) for t in about.topics] == [("/nat/chatter",
                                                                "std_msgs/msg/String")]
    numbers = [int(m.decode().data.split()[1]) for m in read(path)]  # type: ignore[attr-defined]
    assert numbers == list(range(numbers[0], numbers[0] + 20))


async def _open_when_there(url: str, **options: Any) -> WireClient:
    """A raw websocket client of the robot (the relay answers 404 until it is there);
    ``options`` for websockets' connect."""
    deadline = asyncio.get_running_loop().time() + 30
    while True:
        try:
            if not options:
                return await open_wire(url)
            return WireClient(await ws_connect(url, max_size=None, open_timeout=10, **options))
        except (OSError, InvalidStatus):
            if asyncio.get_running_loop().time() > deadline:
                raise
            await asyncio.sleep(0.2)


async def _hears_chatter(wire: WireClient) -> None:
    await wire.expect(op="publish", topic="/nat/chatter", timeout=30)


def _hello(op: dict[str, Any]) -> int:
    return int(op["msg"]["data"].split()[1])


async def test_a_cut_robot_is_reported_and_comes_back(relay_and_robot: Tier) -> None:
    """Blackhole the robot's only link past the lease: the relay's clients are told it went
    away (a status, not silence), then that it is back, and every message its reliable
    20 Hz topic published meanwhile reaches them, in order (its replay window, over these
    mutual-TLS links and the router's access rules), before the new ones."""
    url, ns = relay_and_robot.url, relay_and_robot.ns
    wire = await _open_when_there(url, max_queue=None)
    try:
        await wire.send({"op": "set_level", "level": "info"})  # the return is news, not a warning
        await wire.send({"op": "subscribe", "topic": "/nat/chatter", "type": "std_msgs/msg/String",
                         "queue_length": 1000})
        last = _hello(await wire.expect(op="publish", topic="/nat/chatter", timeout=30))
        _ip("link", "set", ns.host_end, "down")
        cut = time.monotonic()
        gone = await wire.expect(op="status", level="warning", timeout=40)
        assert ROBOT in gone["msg"] and "went away" in gone["msg"]
        _ip("link", "set", ns.host_end, "up")
        published = int(20 * 0.8 * (time.monotonic() - cut))  # at least, at 20 Hz
        back = await wire.expect(op="status", level="info", timeout=60)
        assert ROBOT in back["msg"] and "back" in back["msg"]
        heard = [last]
        while heard[-1] < last + published:
            heard.append(_hello(await wire.expect(op="publish", topic="/nat/chatter",
                                                  timeout=30)))
        assert heard == list(range(last, heard[-1] + 1)), heard
    finally:
        await wire.close()


async def test_a_restarted_router_gets_its_robot_back(relay_and_robot: Tier) -> None:
    """The relay that is the Zenoh router restarts: the robot dials in again by itself, and
    so does the second relay, whose client, connected all along, hears the robot again."""
    t = relay_and_robot
    wire = await _open_when_there(t.url)
    # not read while the router restarts: an unbounded queue keeps its reader (and so its
    # pongs to the relay's keepalive) going meanwhile
    second = await _open_when_there(t.second_url, max_queue=None)
    try:
        for w in (wire, second):
            await w.send({"op": "subscribe", "topic": "/nat/chatter",
                          "type": "std_msgs/msg/String"})
            await _hears_chatter(w)
        # the robot's stream of the topic runs a while before the cut, so its count is well
        # past where the robot's next stream of it, after the restart, starts again
        for _ in range(40):
            await _hears_chatter(second)
        await wire.close()
        await asyncio.to_thread(t.restart_router)  # the clients answer pings meanwhile
        wire = await _open_when_there(t.url)
        await wire.send({"op": "subscribe", "topic": "/nat/chatter", "type": "std_msgs/msg/String"})
        await _hears_chatter(wire)
        await second.expect(op="status", level="warning", timeout=40)  # the robot went away
        # What the robot says now reaches both relays: each of the router relay's next
        # messages reaches the second relay's client too.
        said = [(await wire.expect(op="publish", topic="/nat/chatter"))["msg"]["data"]
                for _ in range(5)]
        for text in said:
            await second.expect(op="publish", topic="/nat/chatter", msg={"data": text})
    finally:
        await wire.close()
        await second.close()
