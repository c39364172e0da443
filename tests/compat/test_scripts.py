"""roslibpy scripts, unchanged but for their import, run through our bridge on the compat layer.

Each script under ``scripts/`` is written the way roslibpy's documentation
writes them. Each runs twice: on ``roslibpy_lite.compat`` and, as proof that
it is plain roslibpy code, on stock roslibpy 2.1.0 (``run_stock.py`` maps the
import to the real package).
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from roslibpy_lite import sync
from tests.helpers import ROOT, BridgeProcess, ros_env, wait_until

HERE = Path(__file__).parent
SCRIPTS = HERE / "scripts"
FLAVOURS = ["compat", "stock"]


def command(flavour: str, script: str) -> list[str]:
    """The command line running ``script`` on the compat layer or on stock roslibpy."""
    path = str(SCRIPTS / script)
    if flavour == "stock":
        return [sys.executable, str(HERE / "run_stock.py"), path]
    return [sys.executable, path]


def run(flavour: str, script: str, bridge: BridgeProcess, **env: str) -> str:
    """Run a script to its end against ``bridge``; returns its output (fails on a non-zero exit)."""
    done = subprocess.run(command(flavour, script), cwd=ROOT, capture_output=True, text=True,
                          timeout=120, env=ros_env(ROSBRIDGE_PORT=str(bridge.port), **env))
    assert done.returncode == 0, done.stdout + done.stderr
    if flavour == "compat":  # nothing logged behind the script's back on the way out
        assert "Traceback" not in done.stderr and "exception" not in done.stderr, done.stderr
    return done.stdout


def wait_seen(bridge: BridgeProcess, what: str, name: str) -> None:
    """Wait until the bridge's ROS graph lists ``name`` among its ``what`` (topics, services or nodes)."""
    srv = "rosapi_msgs/srv/" + what.capitalize()
    with sync.connect(bridge.url) as ros:
        wait_until(lambda: name in ros.call_service(f"/rosapi/{what}", srv)[what], 30,
                   f"{name} in /rosapi/{what}")


@pytest.mark.parametrize("flavour", FLAVOURS)
def test_hello_world(flavour: str, bridge: BridgeProcess) -> None:
    """Ros(host, port).run() connects and terminate() ends the script."""
    assert "Is ROS connected? True" in run(flavour, "hello_world.py", bridge)


@pytest.mark.parametrize("flavour", FLAVOURS)
def test_run_forever_until_terminate(flavour: str, bridge: BridgeProcess) -> None:
    """on_ready runs once connected; terminate() from call_later ends run_forever()."""
    out = run(flavour, "run_forever.py", bridge)
    assert "topics via callback: True" in out and "run_forever returned" in out


@pytest.mark.parametrize("flavour", FLAVOURS)
def test_pubsub_with_threads(flavour: str, bridge: BridgeProcess, topic: str) -> None:
    """A talker thread's messages reach a listener callback, in order; unsubscribe works."""
    out = run(flavour, "pubsub.py", bridge, CHATTER=topic)
    assert out.count("Heard talking: Hello World") >= 5
    assert "subscribed after unsubscribe: False" in out
    assert "in order: True" in out


@pytest.mark.parametrize("flavour", FLAVOURS)
def test_services_both_ways(flavour: str, bridge: BridgeProcess, ros_node: Any, topic: str) -> None:
    """A script serves and calls services (blocking, callback, errback) and calls a ROS node's."""
    from std_srvs.srv import SetBool

    def answer(request: Any, response: Any) -> Any:
        response.success, response.message = True, f"node got {request.data}"
        return response

    ros_node.create_service(SetBool, topic + "_node", answer)
    wait_seen(bridge, "services", topic + "_node")
    out = run(flavour, "services.py", bridge, SERVICE=topic, NODE_SERVICE=topic + "_node")
    assert "Setting speed to True" in out
    assert "Service response: ludicrous" in out
    assert "Callback response: normal" in out
    assert "Refused call raised ServiceException" in out
    assert "Errback called: True" in out
    assert "ROS node answered: node got True" in out


@pytest.mark.parametrize("flavour", FLAVOURS)
def test_introspection(flavour: str, bridge: BridgeProcess, ros_node: Any, topic: str) -> None:
    """get_topics/get_topic_type/get_services/get_service_type/get_nodes see the ROS graph."""
    from std_msgs.msg import String

    ros_node.create_publisher(String, topic, 10)
    wait_seen(bridge, "topics", topic)
    wait_seen(bridge, "nodes", ros_node.get_fully_qualified_name())  # may come after its topic
    out = run(flavour, "introspection.py", bridge, TOPIC=topic,
              NODE=ros_node.get_fully_qualified_name())
    for line in ("topic listed: True", "topic type: std_msgs/msg/String", "typed topics: True",
                 "services listed: True", "service type: rosapi_msgs/srv/Topics",
                 "node listed: True", "callback topics listed: True"):
        assert line in out, out


@pytest.mark.parametrize("flavour", FLAVOURS)
def test_params(flavour: str, bridge: BridgeProcess, ros_node: Any) -> None:
    """A script lists, reads, sets and deletes an rclpy node's parameter."""
    from rcl_interfaces.msg import ParameterDescriptor

    param = f"compat_speed_{flavour}"
    ros_node.declare_parameter(param, 1.5, ParameterDescriptor(dynamic_typing=True))
    name = f"{ros_node.get_fully_qualified_name()}:{param}"
    out = run(flavour, "params.py", bridge, PARAM=name)
    assert "listed: True" in out and "value: 1.5" in out and "after set: 2.5" in out
    assert "deleted: True" in out, out
    assert not ros_node.has_parameter(param)


@pytest.mark.parametrize("flavour", FLAVOURS)
def test_reconnect_events(flavour: str, make_bridge: Callable[..., BridgeProcess], topic: str) -> None:
    """'close' and 'ready' fire when the bridge goes and comes back; the subscription resumes."""
    first = make_bridge()
    proc = subprocess.Popen(command(flavour, "reconnect.py"), cwd=ROOT, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            env=ros_env(ROSBRIDGE_PORT=str(first.port), TOPIC=topic))
    assert proc.stdout is not None
    lines = []
    try:
        lines.append(proc.stdout.readline().strip())
        assert lines[-1] == "ready 1", lines
        first.kill()
        while lines[-1] != "closed":
            lines.append(proc.stdout.readline().strip())
            assert lines[-1], lines
        make_bridge(port=first.port)
        out, err = proc.communicate(timeout=90)
    finally:
        proc.kill()
    assert proc.returncode == 0, err
    assert "ready 2" in out and "resumed after reconnect: True" in out, out + err


@pytest.mark.parametrize("flavour", FLAVOURS)
def test_action_client(flavour: str, bridge: BridgeProcess, ros_node: Any, topic: str) -> None:
    """ActionClient: feedback then the result of an rclpy action server; cancel_goal cancels."""
    from tests.bridge.action_support import FibServer, fib

    servers = [FibServer(ros_node, topic), FibServer(ros_node, topic + "_slow", slow=True)]
    try:
        wait_seen(bridge, "action_servers", topic + "_slow")
        out = run(flavour, "actions.py", bridge, ACTION=topic)
    finally:
        for server in servers:
            server.destroy()
    assert f"Feedback: {fib(5)}" in out
    assert f"Result: {fib(5)} GoalStatus.SUCCEEDED" in out
    assert "Goal ended: GoalStatus.CANCELED" in out and "Canceled in time: True" in out
    assert servers[1].cancel_requests.is_set()
