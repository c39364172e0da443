"""What a relay may ask of a robot is the robot's decision (its relay policy).

A real relay (the Zenoh router, trusting every client: no auth file) and a real robot (an
rclpy bridge and its exporter) held to a policy role; the relay's clients try what the role
does not allow, and the ROS side shows nothing was done.
"""

from __future__ import annotations

import asyncio
import itertools
import subprocess
import sys
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

import pytest
from rcl_interfaces.msg import ParameterDescriptor
from std_msgs.msg import String
from std_srvs.srv import SetBool

import roslibpy_lite
from bridge_server.front.server import Bridge, BridgeConfig, default_node_name
from bridge_server.rclpy_graph.graph import RclpyGraph
from bridge_server.zenoh.exporter import DEFAULT_POLICY, Exporter
from bridge_server.zenoh.link import ZenohOptions
from bridge_server.zenoh.relay import Relay
from rosbridge_core.security import SecurityConfig
from rosbridge_core.security.auth import hash_token, new_token
from rosbridge_core.security.permissions import Role
from roslibpy_lite.exceptions import RemoteError, StatusError
from tests.helpers import ROOT, ros_env
from tests.relay.support import ROBOT, free_port, robot_reachable, until

pytestmark = pytest.mark.timeout(120)

_ROBOTS = itertools.count(1)
"""Numbers the robots' node names: two live nodes of one name mix up graph queries by name."""

LIMITED = Role.from_table("relays", {
    "subscribe": ["*"], "introspection": ["*"], "call_service": ["/rosapi/*", "*_ok"],
    "publish": ["*_echo"], "params": ["*:speed_*"], "deny": {"params": ["*:speed_limit"]},
})
"""A robot's relay policy: calls of *_ok services, publishing *_echo topics, reading and
setting speed_* parameters except speed_limit; no serving, no goals, no take-over."""


@pytest.fixture
async def robot_with(tmp_path: Path) -> AsyncIterator[Callable[..., Any]]:
    """``await robot_with(policy)``: a relay (the router) whose one principal may do
    everything, take_over too, and a robot held to ``policy``; the relay's URL of the robot,
    the principal's token and the exporter. All closed afterwards."""
    opened: list[Any] = []
    token = new_token()
    auth = tmp_path / "relay-auth.toml"
    auth.write_text('[roles.admin]\nall = ["*"]\n[principals.admin]\nrole = "admin"\n'
                    f'token_hash = "{hash_token(token)}"\n')
    auth.chmod(0o600)

    async def make(policy: Role) -> tuple[str, str, Exporter]:
        router = f"tcp/127.0.0.1:{free_port()}"
        relay = Relay(BridgeConfig(port=0, node_name="relay",
                                   security=SecurityConfig(auth_file=str(auth))),
                      ZenohOptions(listen=[router]))
        await relay.start()
        opened.append(relay)
        config = BridgeConfig(websocket=False, port=0, refresh_interval=0.1,
                              node_name=f"{default_node_name()}_robot{next(_ROBOTS)}")
        bridge = Bridge(config, RclpyGraph(asyncio.get_running_loop(), name=config.node_name))
        await bridge.start()
        opened.append(bridge)
        exporter = Exporter(bridge.graph, ROBOT, ZenohOptions(connect=[router]),
                            graph_changed=bridge.graph_changed, snapshot_interval=0.2,
                            policy=lambda: policy)
        exporter.start()
        opened.append(exporter)
        await robot_reachable(relay)
        return f"ws://127.0.0.1:{relay.port}/{ROBOT}", token, exporter

    yield make
    for thing in reversed(opened):
        await thing.close()


async def test_a_robot_holds_relays_to_its_policy(
        robot_with: Callable[..., Any], ros_node: Any, topic: str) -> None:
    """Through a relay that lets its client do anything, the robot refuses what its policy
    does not allow, saying so: a call of another service (its ROS handler never runs), a
    publish on another topic (no publisher made on the robot), a parameter it denies; what
    the policy allows still works."""
    calls: list[str] = []

    def handle(name: str) -> Any:
        def answer(request: Any, response: Any) -> Any:
            calls.append(name)
            response.success = True
            return response
        return answer

    ros_node.create_service(SetBool, f"{topic}_secret", handle("secret"))
    ros_node.create_service(SetBool, f"{topic}_ok", handle("ok"))
    heard: list[str] = []
    ros_node.create_subscription(String, f"{topic}_echo", lambda m: heard.append(m.data), 10)
    ros_node.declare_parameter("speed_limit", 1.0, ParameterDescriptor())
    ros_node.declare_parameter("speed_scale", 0.5, ParameterDescriptor())
    url, token, exporter = await robot_with(LIMITED)
    node = ros_node.get_fully_qualified_name()
    async with roslibpy_lite.connect(url, token=token) as ros:
        reply = await ros.call_service(f"{topic}_ok", "std_srvs/srv/SetBool", {"data": True},
                                       timeout=20)
        assert reply["success"] is True and calls == ["ok"]
        with pytest.raises(RemoteError) as refused:
            await ros.call_service(f"{topic}_secret", "std_srvs/srv/SetBool", {"data": True},
                                   timeout=20)
        assert f"robot {ROBOT}'s relay policy (role relays) does not let relays call " \
            f"service {topic}_secret" in str(refused.value)
        assert calls == ["ok"]

        wrong = await ros.advertise(f"{topic}_cmd", "std_msgs/msg/String")
        await wrong.publish({"data": "drive"})
        await until(lambda: exporter.policy_refused.get(("publish", f"{topic}_cmd")),
                    "the robot to refuse the publish")
        assert not any(t == f"{topic}_cmd" for t, _, _ in exporter.publishers)
        right = await ros.advertise(f"{topic}_echo", "std_msgs/msg/String")
        while not heard:  # a new publisher meets the ROS subscriber in its own time
            await right.publish({"data": "allowed"})
            await asyncio.sleep(0.1)
        assert heard[0] == "allowed"

        assert await ros.graph.get_param(f"{node}:speed_scale") == 0.5
        with pytest.raises(RemoteError, match="does not let relays params"):
            await ros.graph.set_param(f"{node}:speed_limit", 99.0)
    assert ros_node.get_parameter("speed_limit").value == 1.0


@pytest.mark.parametrize("take_over", [False, True], ids=["default", "take_over"])
async def test_a_name_a_ros_node_serves_is_not_taken_over_by_default(
        robot_with: Callable[..., Any], ros_node: Any, topic: str, take_over: bool) -> None:
    """A relay's client serving a name a ROS node of the robot serves: refused by the default
    policy, naming the node's service and take_over (ROS callers keep the node's answer);
    a policy with take_over lets it."""
    ros_node.create_service(SetBool, topic, lambda req, resp: resp)
    policy = Role.from_table("operators", {"all": ["*"]}) if take_over else DEFAULT_POLICY
    url, token, exporter = await robot_with(policy)
    await until(lambda: any(n == topic for n, _ in exporter.graph.service_names_and_types()),
                "the robot to see the node's service")
    async with roslibpy_lite.connect(url, token=token) as ros:
        try:  # the robot's refusal may come while the advertise is awaited, or after it
            server = await ros.advertise_service(topic, "std_srvs/srv/SetBool", lambda req: {})
        except StatusError as exc:
            assert not take_over, exc
            error: BaseException = exc
        else:
            if take_over:
                await until(lambda: exporter.served.get(topic), "the robot to serve it")
                return
            try:
                await until(lambda: server.error is not None, "the refusal to reach the client")
            except AssertionError as exc:  # what the robot decided, for the next reader
                raise AssertionError(
                    f"{exc}; the robot serves {sorted(exporter.served)}, refuses "
                    f"{sorted(exporter.refusing)}, sees other servers "
                    f"{exporter.graph.other_servers(topic)}") from None
            assert server.error is not None
            error = server.error
        assert isinstance(error, StatusError)
        assert f"service {topic} is served by a ROS node of robot {ROBOT}, and its relay policy " \
            "(role relays (default)) lets no relay take it over (take_over)" in str(error)
        assert topic not in exporter.served


def _bridge(*argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "bridge_server", "--no-websocket", *argv],
                          cwd=ROOT, env=ros_env(), capture_output=True, text=True, timeout=60)


def test_relay_role_needs_a_role_of_the_auth_file(tmp_path: Path) -> None:
    """--relay-role without --auth-file is refused at start (status 2), and one the auth file
    does not define is named with the roles it has (status 1)."""
    endpoint = ["--robot", ROBOT, "--zenoh-connect", f"tcp/127.0.0.1:{free_port()}"]
    alone = _bridge(*endpoint, "--relay-role", "relays")
    assert alone.returncode == 2 and "--relay-role" in alone.stderr and "--auth-file" in \
        alone.stderr, alone.stderr
    auth = tmp_path / "auth.toml"
    auth.write_text('[roles.viewer]\nsubscribe = ["*"]\n')
    auth.chmod(0o600)
    missing = _bridge(*endpoint, "--auth-file", str(auth), "--relay-role", "relays")
    assert missing.returncode == 1, missing.stderr
    assert "--relay-role relays: no such role in the auth file (roles: viewer)" in \
        missing.stderr
