"""Every kind of CLI failure: one line on stderr, nothing on stdout, a distinct exit status."""

from __future__ import annotations

import sys
import threading
from collections.abc import Callable
from typing import Any

import pytest

from roslibpy_lite.cli import (
    EXIT_CONNECT,
    EXIT_NOT_FOUND,
    EXIT_REMOTE,
    EXIT_TIMEOUT,
    EXIT_USAGE,
    main,
)
from tests.cli.conftest import Result, Run, closed_port, one_error_line
from tests.cli.test_commands import until_ok
from tests.helpers import BridgeProcess, wait_until

# -- the bridge cannot be reached ----------------------------------------------------------------


def test_no_bridge(cli: Run) -> None:
    """Nothing listening at --url: status 3, naming the URL and the reason."""
    url = f"ws://127.0.0.1:{closed_port()}"
    one_error_line(cli("topic", "list", url=url), EXIT_CONNECT, f"cannot connect to {url}",
                   "is the bridge running?")


def test_malformed_url(cli: Run) -> None:
    """A --url that is not a websocket URL is a usage error."""
    one_error_line(cli("node", "list", url="http//nonsense"), EXIT_USAGE, "bad URL")


def test_connection_lost_during_echo(
    make_bridge: Callable[..., BridgeProcess], capsys: pytest.CaptureFixture[str], topic: str
) -> None:
    """If the bridge dies while echoing, the echo ends with status 3 and says the link was lost."""
    private = make_bridge()
    outcome: list[int] = []
    worker = threading.Thread(target=lambda: outcome.append(main(
        ["topic", "echo", topic, "std_msgs/msg/String", "--url", private.url])))
    worker.start()
    private.wait_for_line(r"client \d+ connected")
    private.kill()
    worker.join(30)
    assert outcome == [EXIT_CONNECT]
    err = capsys.readouterr().err.splitlines()
    assert err == [f"roslibpy-lite: echo {topic}: the connection to {private.url} was lost"]


# -- unknown names ---------------------------------------------------------------------------------


@pytest.mark.parametrize("argv", [
    ("topic", "echo"), ("topic", "type"), ("topic", "info"), ("topic", "hz"),
])
def test_unknown_topic(cli: Run, topic: str, argv: tuple[str, str]) -> None:
    """echo/type/info/hz of a topic nobody has: status 4 naming the topic."""
    one_error_line(cli(*argv, topic, "--wait", "0.2"), EXIT_NOT_FOUND, f"unknown topic {topic}")


@pytest.mark.parametrize("argv", [
    ("service", "type", "{s}"),
    ("service", "call", "{s}", "mult_msgs/srv/MultFloats", "{x: 1.0}"),
])
def test_unknown_service(cli: Run, topic: str, argv: tuple[str, ...]) -> None:
    """type/call of a service nobody serves: status 4 naming the service."""
    args = [topic if a == "{s}" else a for a in argv]
    one_error_line(cli(*args, "--wait", "0.2"), EXIT_NOT_FOUND, f"unknown service {topic}")


def test_unknown_node(cli: Run) -> None:
    """node info of a node not in the graph: status 4."""
    one_error_line(cli("node", "info", "/no_such_node"), EXIT_NOT_FOUND,
                   "unknown node /no_such_node")


def test_unknown_interface(cli: Run) -> None:
    """interface show/list of unknown types or packages: status 4."""
    one_error_line(cli("interface", "show", "nopkg/msg/Nothing", url=None), EXIT_NOT_FOUND,
                   "unknown interface type 'nopkg/msg/Nothing'")
    one_error_line(cli("interface", "list", "nopkg", url=None), EXIT_NOT_FOUND,
                   "unknown interface package nopkg")


# -- bad arguments ---------------------------------------------------------------------------------


CALL = ("service", "call", "/mult_floats", "mult_msgs/srv/MultFloats")


@pytest.mark.parametrize(("argv", "fragment"), [
    ((*CALL, "{x: [1"), "VALUES is not valid YAML at line 1"),
    ((*CALL, "[2.5, 4.0]"), "VALUES must be a mapping"),
    ((*CALL, "{x: abc}"), "bad VALUES for mult_msgs/srv/MultFloats_Request: x: expected float64"),
    ((*CALL, "{z: 1.0}"), "z: expected a field of mult_msgs/srv/MultFloats_Request (x, y)"),
    (("service", "call", "/mult_floats", "MultFloats", "{}"), "'MultFloats' is not a srv type"),
    (("topic", "pub", "/t", "std_msgs/msg/String", "{data: 5}"),
     "bad VALUES for std_msgs/msg/String: data: expected string"),
    (("topic", "pub", "/t", "std_msgs/msg/String", "--rate", "0"), "--rate must be > 0"),
    (("topic", "pub", "/t", "std_msgs/msg/String", "--times", "0"), "--times must be >= 1"),
    (("topic", "pub", "/t", "std_msgs/msg/String", "--once", "--times", "2"),
     "not allowed with argument"),
    (("topic", "echo", "/t", "--count", "0"), "--count must be >= 1"),
    (("topic", "echo", "/t", "--duration", "-1"), "--duration must be > 0"),
    (("topic", "echo", "/t", "std_msgs/Str/ing"), "is not a msg type"),
    (("topic", "hz", "/t", "--window", "0"), "--window must be >= 1"),
    (("topic", "list", "--timeout", "0"), "--timeout must be > 0"),
    (("topic",), "the following arguments are required"),
    (("bogus",), "invalid choice: 'bogus'"),
    (("topic", "list", "--bogus"), "unrecognized arguments: --bogus"),
])
def test_bad_arguments(cli: Run, argv: tuple[str, ...], fragment: str) -> None:
    """Bad command lines, values and fields: status 2, naming what was wrong (no bridge needed)."""
    one_error_line(cli(*argv, url=None), EXIT_USAGE, fragment)


def test_json_only_without_pyyaml(
    cli: Run, monkeypatch: pytest.MonkeyPatch, multiplier: str
) -> None:
    """Without PyYAML, JSON values work and YAML ones get a message saying to install it."""
    monkeypatch.setitem(sys.modules, "yaml", None)
    ok = cli("service", "call", multiplier, "mult_msgs/srv/MultFloats", '{"x": 2.5, "y": 4.0}',
             "--wait", "10")
    assert (ok.code, ok.out) == (0, "result: 10.0\n"), ok
    one_error_line(cli("service", "call", multiplier, "mult_msgs/srv/MultFloats", "{x: 2.5}"),
                   EXIT_USAGE, "not valid JSON", "pip install pyyaml", "[cli] extra")


# -- the other side said no ------------------------------------------------------------------------


def test_publish_with_a_type_the_bridge_lacks(cli: Run, topic: str) -> None:
    """pub with a type no installed package has: the bridge refuses, status 6 with its reason."""
    one_error_line(cli("topic", "pub", topic, "nopkg/msg/Nothing", "{}", "--once"), EXIT_REMOTE,
                   f"the bridge refused to advertise {topic}", "nopkg/msg/Nothing")


def test_echo_with_a_type_the_bridge_lacks(cli: Run, topic: str) -> None:
    """echo with a TYPE no installed package has: the bridge refuses the subscription, status 2,
    as for a type the client itself does not know (a typo in TYPE either way)."""
    one_error_line(cli("topic", "echo", topic, "nopkg/msg/Nothing", "--duration", "10"),
                   EXIT_USAGE, "nopkg/msg/Nothing")


def test_call_with_a_type_the_bridge_lacks(cli: Run, multiplier: str) -> None:
    """call of a real service with an unknown type: the call fails, status 6 with the reason."""
    result = cli("service", "call", multiplier, "nopkg/srv/Nothing", "{}", "--wait", "10")
    one_error_line(result, EXIT_REMOTE, f"service {multiplier} failed", "nopkg/srv/Nothing")


def test_call_timeout(cli: Run, ros_node: Any, topic: str) -> None:
    """A service slower than --call-timeout: status 5 saying no answer came in time."""
    from mult_msgs.srv import MultFloats
    from rclpy.callback_groups import ReentrantCallbackGroup

    release = threading.Event()

    def slow(request: Any, response: Any) -> Any:
        release.wait(10)
        return response

    ros_node.create_service(MultFloats, topic, slow, callback_group=ReentrantCallbackGroup())
    try:
        result = cli("service", "call", topic, "mult_msgs/srv/MultFloats", "{}",
                     "--call-timeout", "0.5", "--wait", "10")
    finally:
        release.set()
    one_error_line(result, EXIT_TIMEOUT, f"call {topic}: no answer within 0.5 s")


def test_errors_do_not_disturb_the_bridge(cli: Run, multiplier: str) -> None:
    """After all of the above, the bridge still answers a good call."""
    result: list[Result] = []
    def good_call() -> bool:
        result.append(cli("service", "call", multiplier, "mult_msgs/srv/MultFloats",
                          "{x: 3.0, y: 3.0}"))
        return result[-1].code == 0

    wait_until(good_call, timeout=15, what="a good call")
    assert result[-1].out == "result: 9.0\n"


def test_unknown_topic_suggests_the_close_one(cli: Run, ros_node: Any, topic: str) -> None:
    """`topic echo /imuu` when /imu exists: exit 4, and the message names the close topic."""
    from std_msgs.msg import String

    ros_node.create_publisher(String, topic, 10)
    until_ok(cli, "topic", "type", topic, check=lambda r: r.code == 0)
    result = cli("topic", "echo", topic + "x", "--count", "1")
    one_error_line(result, EXIT_NOT_FOUND, f"unknown topic {topic}x", f"did you mean {topic}?")


@pytest.mark.parametrize("bad", ["sensor_msgs/msg/Imuu", "sensor_msg/msg/Imu"])
def test_type_typos_exit_with_one_code(cli: Run, bad: str) -> None:
    """A typo in TYPE exits 2 whether the client or the bridge noticed it."""
    result = cli("topic", "echo", "/imu_typo_probe", bad, "--count", "1", "--timeout", "10")
    one_error_line(result, EXIT_USAGE, bad)


def test_interface_show_says_the_case_is_wrong(cli: Run) -> None:
    """`interface show sensor_msgs/msg/imu` names the right spelling, not the name's format."""
    result = cli("interface", "show", "sensor_msgs/msg/imu")
    one_error_line(result, EXIT_NOT_FOUND, "did you mean 'sensor_msgs/msg/Imu'?")


@pytest.mark.parametrize("argv", [
    ("bag", "info", "run.mcap"),
    ("bag", "record", "/imu", "-o", "run.mcap"),
    ("bag", "play", "run.mcap"),
])
def test_bag_without_the_mcap_library_says_only_how_to_install_it(
    argv: tuple[str, ...], capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Without mcap every bag command says the extra is missing and the pip line, before it
    looks at the file or the bridge (no "not a readable MCAP file", no connection error)."""
    monkeypatch.setitem(sys.modules, "mcap", None)  # import mcap raises ImportError
    code = main([*argv, "--url", f"ws://127.0.0.1:{closed_port()}"])
    captured = capsys.readouterr()
    one_error_line(Result(code, captured.out, captured.err), EXIT_USAGE)
    assert captured.err == ("roslibpy-lite: the mcap extra is not installed: "
                            "pip install 'roslibpy-lite[mcap]'\n")
