"""The compat layer has roslibpy's names and signatures, and refuses what it does not cover clearly."""

from __future__ import annotations

import inspect
import threading
from pathlib import Path
from typing import Any

import pytest
import roslibpy
import roslibpy.ros2

import roslibpy_lite.compat as compat
from roslibpy_lite import ConnectionClosed, NotAuthenticated
from tests.helpers import BridgeProcess, free_port, threads_since
from tests.security.support import make_auth_file

NOT_COVERED = {"set_default_transport"}
"""roslibpy names the compat layer does not offer (docs/compat.md lists them)."""


def parameters(fn: Any) -> list[tuple[str, Any]]:
    """The names and defaults of a callable's parameters (annotations aside)."""
    return [(p.name, p.default) for p in inspect.signature(fn).parameters.values()]


def test_exports_roslibpys_names() -> None:
    """Every public name of roslibpy (but the listed exceptions) exists in roslibpy_lite.compat."""
    wanted = {n for n in roslibpy.__all__ if not n.startswith("__")} - NOT_COVERED
    assert wanted <= set(compat.__all__)


@pytest.mark.parametrize("name", ["Ros", "Topic", "Service", "Param", "Time", "Header",
                                  "Message", "ServiceRequest", "ServiceResponse"])
def test_signatures_match_roslibpy(name: str) -> None:
    """Constructors and public methods take the same parameters, with the same defaults."""
    ours, theirs = getattr(compat, name), getattr(roslibpy, name)
    for attr, member in vars(theirs).items():
        if (attr.startswith("_") and attr != "__init__") or not callable(member):
            continue
        if not hasattr(ours, attr):
            assert name == "Ros" and attr in {"send_on_ready", "blocking_call_from_thread",
                                              "get_service_request_callback", "call_sync_service",
                                              "call_async_service", "call_async_action",
                                              "set_status_level", "authenticate"}, attr
            continue
        assert parameters(getattr(ours, attr)) == parameters(member), f"{name}.{attr}"


def test_values_behave_like_roslibpys() -> None:
    """Time, Header and ros2.Header hold the same values as roslibpy's."""
    assert dict(compat.Time(3, 500)) == dict(roslibpy.Time(3, 500))
    assert compat.Time.from_sec(1.5).to_nsec() == roslibpy.Time.from_sec(1.5).to_nsec()
    stamp = {"secs": 1, "nsecs": 2}
    assert dict(compat.Header(7, stamp, "map")) == dict(roslibpy.Header(7, stamp, "map"))
    assert dict(compat.ros2.Header(stamp, "map")) == dict(roslibpy.ros2.Header(stamp, "map"))
    with pytest.raises(ValueError, match="integer"):
        compat.Time(1.5, 0)


def test_uncovered_parts_say_so(bridge: BridgeProcess) -> None:
    """Headers other than a bearer token raise NotImplementedError naming them."""
    with pytest.raises(NotImplementedError, match="X-Robot") as caught:
        compat.Ros("127.0.0.1", bridge.port, headers={"X-Robot": "secret-value"})
    assert "secret-value" not in str(caught.value)


def test_action_client_signatures() -> None:
    """ActionClient and its methods take roslibpy's parameters."""
    assert parameters(compat.ActionClient) == parameters(roslibpy.ActionClient)
    for method in ("send_goal", "cancel_goal", "wait_goal"):
        assert parameters(getattr(compat.ActionClient, method)) == parameters(
            getattr(roslibpy.ActionClient, method)), method


def test_blocking_call_inside_a_callback_and_clean_terminate(bridge: BridgeProcess, topic: str) -> None:
    """A topic callback may make a blocking call; terminate stops every thread the Ros started."""
    threads = set(threading.enumerate())
    ros = compat.Ros(bridge.url)  # a URL works as the host, as in roslibpy
    ros.run()
    got: list[Any] = []
    done = threading.Event()

    def on_message(message: dict[str, Any]) -> None:
        got.append(ros.get_topic_type(topic))
        done.set()

    compat.Topic(ros, topic, "std_msgs/String").subscribe(on_message)
    talker = compat.Topic(ros, topic, "std_msgs/String")
    while not done.wait(0.2):
        talker.publish(compat.Message({"data": "hi"}))
    assert got == ["std_msgs/msg/String"]
    ros.terminate()
    assert not ros.is_connected
    assert not threads_since(threads), threads_since(threads)


def test_close_then_run_reconnects(bridge: BridgeProcess) -> None:
    """After close() the Ros is disconnected and emits 'closing'; run() connects it again."""
    events: list[str] = []
    closed = threading.Event()
    ros = compat.Ros("127.0.0.1", bridge.port)
    ros.on("closing", lambda *args: events.append("closing"))
    ros.on("close", lambda *args: closed.set())
    try:
        ros.run()
        assert ros.is_connected
        ros.close()
        assert not ros.is_connected and closed.wait(10)
        assert events == ["closing"]
        ros.run()
        assert ros.is_connected and "/rosapi/topics" in ros.get_services()
    finally:
        ros.terminate()


def test_bearer_header_is_the_token(make_bridge: Any, tmp_path: Path) -> None:
    """headers={'Authorization': 'Bearer ...'} authenticates; a refused token fails run() at once."""
    auth = make_auth_file(tmp_path)
    bridge = make_bridge("--auth-file", str(auth.path))
    ros = compat.Ros("127.0.0.1", bridge.port,
                     headers={"Authorization": f"Bearer {auth.tokens['admin']}"})
    try:
        ros.run()
        assert "/rosapi/topics" in ros.get_services()
    finally:
        ros.terminate()
    errors: list[Exception] = []
    refused = compat.Ros("127.0.0.1", bridge.port, headers={"Authorization": "Bearer wrong-token"})
    refused.on("error", errors.append)
    try:
        with pytest.raises(NotAuthenticated) as caught:
            refused.run()
        assert "wrong-token" not in str(caught.value)
    finally:
        refused.terminate()
    assert len(errors) == 1


def test_operations_after_terminate_raise_connection_closed() -> None:
    """After terminate, publish/subscribe/call raise ConnectionClosed; cleanups and call_later are no-ops."""
    ros = compat.Ros("ws://127.0.0.1:1")  # never connected: nothing is needed to terminate
    topic = compat.Topic(ros, "/chatter", "std_msgs/String")
    ros.terminate()
    with pytest.raises(ConnectionClosed, match="terminated; make a new Ros"):
        topic.subscribe(lambda msg: None)
    topic.unsubscribe()  # cleanup after terminate, as scripts do, is harmless
    ros.call_later(0.01, lambda: None)  # never runs, raises nothing (roslibpy's stopped reactor)
    with pytest.raises(ConnectionClosed, match="terminated; make a new Ros"):
        topic.publish(compat.Message({"data": "x"}))
    with pytest.raises(ConnectionClosed, match="call /add: the client is closed"):
        compat.Service(ros, "/add", "example_interfaces/AddTwoInts").call({"a": 1, "b": 2})


def test_wrong_port_says_where_and_what_to_check() -> None:
    """run() against a port nobody serves fails naming the URL and what to check, not only
    'Failed to connect to ROS'."""
    port = free_port()
    ros = compat.Ros(host="127.0.0.1", port=port)
    try:
        with pytest.raises(compat.RosTimeoutError) as info:
            ros.run(timeout=2)
    finally:
        ros.terminate()
    text = str(info.value)
    assert f"ws://127.0.0.1:{port}" in text and "rosbridge server" in text


def test_byte_arrays_are_base64_text_as_roslibpy_gives_them(
    bridge: BridgeProcess, ros_node: Any, topic: str
) -> None:
    """The drop-in keeps roslibpy's shape for uint8[] fields under JSON: base64 text in a
    subscribed message and in a service response (the native client gives bytes)."""
    from sensor_msgs.msg import Image
    from test_msgs.srv import Arrays

    def arrays(request: Any, response: Any) -> Any:
        response.uint8_values = [1, 2, 255]
        return response

    ros_node.create_service(Arrays, topic + "_arrays", arrays)
    pub = ros_node.create_publisher(Image, topic, 10)
    ros = compat.Ros(bridge.url)
    ros.run()
    try:
        got: list[Any] = []
        heard = threading.Event()

        def on_image(message: dict[str, Any]) -> None:
            got.append(message)
            heard.set()

        compat.Topic(ros, topic, "sensor_msgs/Image").subscribe(on_image)
        while not heard.wait(0.2):
            pub.publish(Image(height=1, width=3, encoding="mono8", step=3, data=[1, 2, 255]))
        assert got[0]["data"] == "AQL/"
        service = compat.Service(ros, topic + "_arrays", "test_msgs/Arrays")
        response = service.call(compat.ServiceRequest({}), timeout=30)
        assert response is not None and response["uint8_values"] == "AQL/"
    finally:
        ros.terminate()
