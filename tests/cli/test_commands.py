"""Every CLI subcommand against the real bridge, with rclpy nodes on the ROS side."""

from __future__ import annotations

import json
import re
import threading
from collections.abc import Iterator
from typing import Any

import pytest

from msgs import runtime
from tests.cli.conftest import Result, Run, one_error_line
from tests.helpers import wait_until


def full_name(node: Any) -> str:
    """The node's fully qualified name."""
    ns = node.get_namespace().rstrip("/")
    return f"{ns}/{node.get_name()}"


@pytest.fixture
def talker(ros_node: Any, topic: str) -> Iterator[list[str]]:
    """An rclpy publisher of std_msgs/String 'hello N' on ``topic`` at 20 Hz; yields what it sent."""
    from std_msgs.msg import String

    pub = ros_node.create_publisher(String, topic, 10)
    sent: list[str] = []

    def tick() -> None:
        text = f"hello {len(sent)}"
        sent.append(text)
        pub.publish(String(data=text))

    timer = ros_node.create_timer(0.05, tick)
    yield sent
    ros_node.destroy_timer(timer)
    ros_node.destroy_publisher(pub)


def until_ok(cli: Run, *argv: str, check: Any = None, timeout: float = 15) -> Result:
    """Run the CLI until it succeeds (and ``check(result)`` holds): the graph needs discovery."""
    last: list[Result] = []

    def attempt() -> bool:
        result = cli(*argv)
        last[:] = [result]
        return result.code == 0 and (check is None or bool(check(result)))

    wait_until(attempt, timeout=timeout, what=f"roslibpy-lite {' '.join(argv)}: {last}")
    return last[0]


# -- topic ------------------------------------------------------------------------------------------


def test_topic_list_shows_a_ros_publisher(cli: Run, talker: list[str], topic: str) -> None:
    """topic list names the rclpy topic; -t adds its type; --json gives name/type objects."""
    until_ok(cli, "topic", "list", check=lambda r: topic in r.lines)
    typed = cli("topic", "list", "-t")
    assert f"{topic} [std_msgs/msg/String]" in typed.lines
    listed = json.loads(cli("topic", "list", "--json").out)
    assert {"name": topic, "type": "std_msgs/msg/String"} in listed


def test_topic_type(cli: Run, talker: list[str], topic: str) -> None:
    """topic type prints the type of a topic an rclpy node publishes."""
    result = until_ok(cli, "topic", "type", topic, "--wait", "10")
    assert result.out == "std_msgs/msg/String\n"


def test_topic_info_counts_and_names_nodes(
    cli: Run, talker: list[str], topic: str, ros_node: Any
) -> None:
    """topic info shows the type and the publishing node (-v names it; --json has both lists)."""
    me = f"  {full_name(ros_node)}"  # the node's name is discovered after its publisher
    result = until_ok(cli, "topic", "info", topic, "-v", "--wait", "10",
                      check=lambda r: me in r.lines)
    assert result.lines == ["Type: std_msgs/msg/String", "Publisher count: 1",
                            f"  {full_name(ros_node)}", "Subscription count: 0"]
    info = json.loads(cli("topic", "info", topic, "--json").out)  # (discovered by now)
    assert info == {"name": topic, "type": "std_msgs/msg/String",
                    "publishers": [full_name(ros_node)], "subscribers": []}


def test_topic_echo_prints_yaml_documents(cli: Run, talker: list[str], topic: str) -> None:
    """topic echo (type looked up) prints each message as YAML ended by '---', --count stops it."""
    result = cli("topic", "echo", topic, "--count", "2", "--wait", "10")
    assert result.code == 0, result
    docs = result.out.split("---\n")
    assert docs[-1] == "" and len(docs) == 3
    matches = [re.fullmatch(r"data: 'hello (\d+)'\n", d) for d in docs[:2]]
    numbers = [int(m[1]) for m in matches if m]
    assert len(numbers) == 2 and numbers[1] == numbers[0] + 1, result.out
    assert f"hello {numbers[1]}" in talker


def test_topic_echo_json_lines(cli: Run, talker: list[str], topic: str) -> None:
    """topic echo --json prints one JSON object per message."""
    result = cli("topic", "echo", topic, "std_msgs/msg/String", "--count", "3", "--json")
    assert result.code == 0, result
    msgs = [json.loads(line) for line in result.lines]
    assert len(msgs) == 3 and all(m["data"].startswith("hello ") for m in msgs)
    numbers = [int(m["data"].split()[1]) for m in msgs]
    assert numbers == sorted(numbers)


def test_topic_echo_duration_ends_without_messages(cli: Run, topic: str) -> None:
    """With a TYPE and no publisher, --duration ends the echo with status 0 and no output."""
    result = cli("topic", "echo", topic, "std_msgs/msg/String", "--duration", "0.5")
    assert (result.code, result.out, result.err) == (0, "", "")


def test_topic_pub_once_reaches_a_ros_subscriber(cli: Run, ros_node: Any, topic: str) -> None:
    """topic pub --once waits for the rclpy subscriber, publishes one message and exits 0."""
    from std_msgs.msg import String

    got: list[str] = []
    arrived = threading.Event()

    def on_msg(msg: Any) -> None:
        got.append(msg.data)
        arrived.set()

    ros_node.create_subscription(String, topic, on_msg, 10)
    result = cli("topic", "pub", topic, "std_msgs/msg/String", "{data: hi there}", "--once")
    assert (result.code, result.out) == (0, 'publishing #1: {"data": "hi there"}\n'), result
    assert arrived.wait(10), "the rclpy subscriber got nothing"
    assert got == ["hi there"]


def test_topic_pub_times_publishes_that_many(cli: Run, ros_node: Any, topic: str) -> None:
    """topic pub --times 3 -r 20 publishes exactly three messages, in order."""
    from std_msgs.msg import Int32

    got: list[int] = []
    ros_node.create_subscription(Int32, topic, lambda m: got.append(m.data), 10)
    result = cli("topic", "pub", topic, "std_msgs/msg/Int32", '{"data": 7}', "--times", "3",
                 "-r", "20", "-q")
    assert (result.code, result.out, result.err) == (0, "", ""), result
    wait_until(lambda: len(got) >= 3, timeout=10, what="three messages")
    assert got == [7, 7, 7]


def test_topic_echo_latched_topic_prints_the_last_message(
    cli: Run, bridge: Any, ros_node: Any, topic: str
) -> None:
    """A client's latched topic given three messages: a late echo --count 1 prints the third,
    and a late rclpy transient-local subscriber asking for 10 gets only the third."""
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from std_msgs.msg import String

    from roslibpy_lite import sync

    with sync.connect(bridge.url) as ros:
        pub = ros.advertise(topic, "std_msgs/msg/String", latch=True)
        for label in ("first", "second", "third"):
            pub.publish({"data": label})
        # the bridge handles a connection's ops in order: once this answers, all 3 are out
        ros.call_service("/rosapi/topics", "rosapi_msgs/srv/Topics", {})
        result = cli("topic", "echo", topic, "--count", "1", "--json", "--wait", "10")
        assert (result.code, result.lines) == (0, ['{"data":"third"}']), result
        got: list[str] = []
        ros_node.create_subscription(
            String, topic, lambda m: got.append(m.data),
            QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL))  # type: ignore[no-untyped-call]
        wait_until(lambda: got, timeout=10, what="the latched message")
        # a second publish: everything replayed was delivered before it
        pub.publish({"data": "fourth"})
        wait_until(lambda: "fourth" in got, timeout=10, what="the live message")
        assert got == ["third", "fourth"]


def test_topic_hz_reports_rate_statistics(cli: Run, talker: list[str], topic: str) -> None:
    """topic hz --json reports rate, min, max, std dev and window; the text form is ros2's."""
    result = cli("topic", "hz", topic, "std_msgs/msg/String", "--count", "25", "--json")
    assert result.code == 0, result
    reports = [json.loads(line) for line in result.lines]
    assert reports and set(reports[-1]) == {"rate", "min", "max", "std_dev", "window"}
    last = reports[-1]
    assert last["window"] == 24
    assert last["rate"] > 0 and 0 <= last["min"] <= last["max"]
    text = cli("topic", "hz", topic, "std_msgs/msg/String", "--count", "5")
    assert text.code == 0, text
    assert re.fullmatch(r"average rate: \d+\.\d{3}", text.lines[-2]), text.out
    assert re.fullmatch(r"\tmin: \d+\.\d{3}s max: \d+\.\d{3}s std dev: \d+\.\d{5}s window: 4",
                        text.lines[-1]), text.out


# -- service ---------------------------------------------------------------------------------------


def test_service_list_and_type(cli: Run, multiplier: str) -> None:
    """service list (-t, --json) and service type show an rclpy service and its type."""
    until_ok(cli, "service", "list", check=lambda r: multiplier in r.lines)
    assert f"{multiplier} [mult_msgs/srv/MultFloats]" in cli("service", "list", "-t").lines
    listed = json.loads(cli("service", "list", "--json").out)
    assert {"name": multiplier, "type": "mult_msgs/srv/MultFloats"} in listed
    assert {"name": "/rosapi/topics", "type": "rosapi_msgs/srv/Topics"} in listed
    assert cli("service", "type", multiplier).out == "mult_msgs/srv/MultFloats\n"


def test_service_call_prints_the_response(cli: Run, multiplier: str) -> None:
    """service call with YAML values prints the response as YAML; --json as one JSON line."""
    result = cli("service", "call", multiplier, "mult_msgs/srv/MultFloats", "{x: 2.5, y: 4.0}",
                 "--wait", "10")
    assert (result.code, result.out, result.err) == (0, "result: 10.0\n", ""), result
    as_json = cli("service", "call", multiplier, "mult_msgs/MultFloats", '{"x": 3, "y": -2}',
                  "--json")
    assert (as_json.code, json.loads(as_json.out)) == (0, {"result": -6.0}), as_json


def test_service_call_without_values_sends_defaults(cli: Run, multiplier: str) -> None:
    """Omitted VALUES mean the default request (0 * 0)."""
    result = cli("service", "call", multiplier, "mult_msgs/srv/MultFloats", "--wait", "10")
    assert (result.code, result.out) == (0, "result: 0.0\n"), result


# -- node ------------------------------------------------------------------------------------------


def test_node_list_and_info(cli: Run, ros_node: Any, talker: list[str], topic: str) -> None:
    """node list names the rclpy node and the bridge; node info shows what the node publishes."""
    me = full_name(ros_node)
    listed = until_ok(cli, "node", "list", check=lambda r: me in r.lines)
    assert any(line.startswith("/roslibpy_lite_bridge_") for line in listed.lines), listed
    assert me in json.loads(cli("node", "list", "--json").out)
    info = until_ok(cli, "node", "info", me, check=lambda r: f"    {topic}" in r.lines)
    assert info.lines[0] == me and "  Publishers:" in info.lines
    details = json.loads(cli("node", "info", me, "--json").out)
    assert topic in details["publishing"] and details["name"] == me


# -- interface -------------------------------------------------------------------------------------


def test_interface_show_expands_nested_types(cli: Run) -> None:
    """interface show prints the definition with nested types indented by a tab, like ros2."""
    result = cli("interface", "show", "std_msgs/msg/Header", url=None)
    assert result.code == 0, result
    lines = result.lines
    stamp = lines.index("builtin_interfaces/Time stamp")
    assert "\tint32 sec" in lines[stamp:] and "\tuint32 nanosec" in lines[stamp:]
    assert lines[-1] == "string frame_id"
    raw = cli("interface", "show", "std_msgs/Header", "--raw", url=None)
    assert "\tint32 sec" not in raw.lines and "builtin_interfaces/Time stamp" in raw.lines


def test_interface_show_service(cli: Run) -> None:
    """A service shows request, '---', response."""
    result = cli("interface", "show", "mult_msgs/srv/MultFloats", url=None)
    assert result.lines == ["# Multiply two floats.", "float64 x", "float64 y", "---",
                            "float64 result"]


def test_interface_list(cli: Run) -> None:
    """interface list names message, service and action types; a package filter narrows it."""
    everything = cli("interface", "list", url=None).lines
    assert {"std_msgs/msg/String", "mult_msgs/srv/MultFloats"} <= set(everything)
    assert cli("interface", "list", "mult_msgs", url=None).lines == [
        "mult_msgs/action/IntegrateImu", "mult_msgs/srv/MultFloats"]


def test_interface_list_remote_adds_the_bridges_types_marked(cli: Run) -> None:
    """interface list --remote adds the bridge's types; the robot's own (robot_msgs: built
    into the bridge's venv, not in msgs) are marked as only the bridge's; without --remote
    a package only the bridge has is unknown here, and the error says --remote asks it."""
    from roslibpy_lite.cli.interface import BRIDGE_ONLY

    both = cli("interface", "list", "--remote")
    assert both.code == 0, both
    assert "robot_msgs/msg/Status" + BRIDGE_ONLY in both.lines
    assert "std_msgs/msg/String" in both.lines  # known on both sides: not marked
    assert all(not line.startswith("std_msgs/") or not line.endswith(BRIDGE_ONLY)
               for line in both.lines)
    robot = cli("interface", "list", "robot_msgs", "-r")
    assert robot.code == 0 and robot.lines and all(
        line.startswith("robot_msgs/") and line.endswith(BRIDGE_ONLY) for line in robot.lines)
    local = cli("interface", "list", "robot_msgs", url=None)
    assert local.code == 4 and "--remote asks the bridge" in local.err, local


def test_interface_list_remote_filters_by_whole_package_name(cli: Run) -> None:
    """interface list PACKAGE -r takes PACKAGE as a whole package name, not a prefix:
    'robot' lists none of the bridge's robot_msgs types and is an unknown package."""
    assert any(line.startswith("robot_msgs/") for line in cli("interface", "list", "-r").lines)
    robot = cli("interface", "list", "robot", "-r")
    assert not any(line.startswith("robot_msgs/") for line in robot.lines), robot
    one_error_line(robot, 4, "unknown interface package robot here or on the bridge")


def test_list_hides_hidden_topics_and_services(cli: Run, ros_node: Any, topic: str) -> None:
    """topic list and service list hide names with a part starting with _ (an action's
    /_action/ topics and services, a /_private topic) as ros2 does; --include-hidden shows
    them."""
    from std_msgs.msg import String

    from tests.bridge.action_support import FibServer

    server = FibServer(ros_node, topic)
    ros_node.create_publisher(String, f"{topic}/_private", 10)
    ros_node.create_publisher(String, f"{topic}/shown", 10)
    try:
        hidden = {f"{topic}/_action/feedback", f"{topic}/_action/status", f"{topic}/_private"}
        every = until_ok(cli, "topic", "list", "--include-hidden",
                         check=lambda r: hidden | {f"{topic}/shown"} <= set(r.lines))
        listed = cli("topic", "list")
        assert f"{topic}/shown" in listed.lines and not hidden & set(listed.lines), listed
        assert not [n for n in listed.lines if "/_" in n]
        assert {n for n in every.lines if "/_" not in n} <= set(listed.lines)
        goal = f"{topic}/_action/send_goal"
        until_ok(cli, "service", "list", "--include-hidden-services",
                 check=lambda r: goal in r.lines)
        services = cli("service", "list", "-t")
        assert services.code == 0 and goal not in services.out
        assert not [n for n in services.lines if "/_" in n]
        assert any(n.startswith("/rosapi/topics ") for n in services.lines)
    finally:
        server.destroy()


def test_url_from_the_environment(
    cli: Run, monkeypatch: pytest.MonkeyPatch, bridge: Any
) -> None:
    """Without --url the CLI uses $ROSLIBPY_LITE_URL."""
    monkeypatch.setenv("ROSLIBPY_LITE_URL", bridge.url)
    result = cli("node", "list", url=None)
    assert result.code == 0 and bridge.node_name in result.lines, result


def test_help_documents_the_exit_codes(cli: Run) -> None:
    """--help exits 0 and lists every exit status with its meaning."""
    from roslibpy_lite.cli import EXIT_CODES

    result = cli("--help", url=None)
    assert result.code == 0
    for code, meaning in EXIT_CODES.items():
        assert f"  {code:<4} {meaning}" in result.out


def test_topic_echo_shows_byte_arrays_as_integers(cli: Run, ros_node: Any, topic: str) -> None:
    """uint8[] (base64 on the wire) prints as a list of integers, like ros2; --json keeps base64."""
    from sensor_msgs.msg import Image

    pub = ros_node.create_publisher(Image, topic, 10)

    def tick() -> None:
        msg = Image(height=1, width=3, encoding="mono8", step=3, data=[1, 2, 255])
        pub.publish(msg)

    timer = ros_node.create_timer(0.05, tick)
    try:
        image = cli("topic", "echo", topic, "sensor_msgs/msg/Image", "--count", "1")
        wire = cli("topic", "echo", topic, "sensor_msgs/msg/Image", "--count", "1", "--json")
    finally:
        ros_node.destroy_timer(timer)
    assert image.code == 0, image
    assert "data:\n- 1\n- 2\n- 255\n---\n" in image.out and "encoding: 'mono8'" in image.out
    assert json.loads(wire.out)["data"] == "AQL/"  # --json keeps the wire form (base64)


def test_topic_echo_shows_nan(cli: Run, ros_node: Any, topic: str) -> None:
    """A NaN float field prints as .nan in YAML and null in --json."""
    from std_msgs.msg import Float64

    pub = ros_node.create_publisher(Float64, topic, 10)
    timer = ros_node.create_timer(0.05, lambda: pub.publish(Float64(data=float("nan"))))
    try:
        shown = cli("topic", "echo", topic, "std_msgs/msg/Float64", "--count", "1")
        wire = cli("topic", "echo", topic, "std_msgs/msg/Float64", "--count", "1", "--json")
    finally:
        ros_node.destroy_timer(timer)
    assert (shown.code, shown.out) == (0, "data: .nan\n---\n"), shown
    assert (wire.code, wire.out) == (0, '{"data":null}\n'), wire


def test_interface_show_asks_the_bridge_for_types_msgs_lacks(
    cli: Run, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A type msgs does not generate (but the robot has) is shown from the bridge's rosapi."""
    # As in a fresh CLI process: an in-process bridge earlier in this run (a Foxglove hub
    # building its channels) may have registered the package's types with msgs.dynamic.
    monkeypatch.setattr(runtime, "_CACHE", {name: cls for name, cls in runtime._CACHE.items()
                                            if not name.startswith("type_description_interfaces/")})
    shown = cli("interface", "show", "type_description_interfaces/msg/KeyValue")
    assert shown.code == 0, shown
    assert shown.lines == ["string key", "string value"]
    srv = cli("interface", "show", "type_description_interfaces/srv/GetTypeDescription")
    assert srv.code == 0, srv
    assert "string type_name" in srv.lines and "---" in srv.lines
    assert "bool successful" in srv.lines
    missing = cli("interface", "show", "nothing_here/msg/Nope")
    assert missing.code == 4 and "does not know it either" in missing.err, missing
