"""Service scenarios: calling ROS services through a stock client and serving them from it
(sync, async, relative names, failing handlers, timeouts, concurrent calls, bad arguments).
"""

from __future__ import annotations

import threading
from typing import Any

from tests.helpers import wait_until
from tests.peers.peer import PeerError, PeerProcess
from tests.peers.scenarios.support import (
    DEADLINE,
    _call_from_ros,
    _call_new_service,
    _module,
)

# -- services ---------------------------------------------------------------------------------


def call_setbool(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer calls an rclpy std_srvs/SetBool service (no type given) and gets its answer."""
    from std_srvs.srv import SetBool

    seen: list[bool] = []

    def serve(request: Any, response: Any) -> Any:
        seen.append(request.data)
        response.success = not request.data
        response.message = f"rclpy got data={request.data}"
        return response

    node.create_service(SetBool, topic, serve)
    assert _call_new_service(peer, topic, {"data": True}) == {
        "success": False, "message": "rclpy got data=True",
    }
    assert peer.request("call", service=topic, args={"data": False}) == {
        "success": True, "message": "rclpy got data=False",
    }
    assert seen == [True, False]


def call_mult(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer calls an rclpy mult_msgs/MultFloats service and gets the product back."""
    from mult_msgs.srv import MultFloats

    def serve(request: Any, response: Any) -> Any:
        response.result = request.x * request.y
        return response

    node.create_service(MultFloats, topic, serve)
    assert _call_new_service(peer, topic, {"x": 2.5, "y": -4.0}) == {"result": -10.0}


def call_missing(peer: PeerProcess, topic: str) -> None:
    """Calling a service nobody offers fails promptly through the client's error path."""
    missing = topic + "_nobody_serves_this"
    try:
        value = peer.request("call", service=missing, args={}, timeout=20.0)
    except PeerError as exc:
        text = str(exc)
        assert "Timeout" not in text, f"the client timed out instead of being told: {text}"
        assert missing in text, f"the error does not name the service: {text}"
    else:
        raise AssertionError(f"call to {missing} succeeded with {value!r}")


def serve_setbool(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer serves std_srvs/SetBool; an rclpy client's calls reach it and get its answers."""
    from std_srvs.srv import SetBool

    peer.request("advertise_service", service=topic, type="std_srvs/srv/SetBool", handler="setbool")
    client_name = "roslibpy" if peer.name.startswith("roslibpy") else "roslibjs"
    for data in (True, False):
        response = _call_from_ros(node, SetBool, topic, SetBool.Request(data=data))
        assert response.success is data
        assert response.message == f"{client_name} got data={data}"
    requests = [e for e in peer.new_events() if e.get("event") == "request" and e["service"] == topic]
    assert [e["args"] for e in requests] == [{"data": True}, {"data": False}]


def serve_mult(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer serves mult_msgs/MultFloats (short type spelling); an rclpy client gets x*y."""
    from mult_msgs.srv import MultFloats

    peer.request("advertise_service", service=topic, type="mult_msgs/MultFloats", handler="mult")
    response = _call_from_ros(node, MultFloats, topic, MultFloats.Request(x=1.5, y=6.0))
    assert response.result == 9.0


def unadvertise_service(peer: PeerProcess, node: Any, topic: str) -> None:
    """After the peer unadvertises its service, it leaves the ROS graph."""
    from std_srvs.srv import SetBool

    peer.request("advertise_service", service=topic, type="std_srvs/srv/SetBool", handler="setbool")
    response = _call_from_ros(node, SetBool, topic, SetBool.Request(data=True))
    assert response.success is True
    peer.request("unadvertise_service", service=topic)

    def gone() -> bool:
        names = {name for name, _types in node.get_service_names_and_types()}
        return topic not in names

    wait_until(gone, DEADLINE, f"{topic} to leave the graph")


# -- robustness through stock clients ---------------------------------------------------------


def killed_client_service_goes(peer: PeerProcess, node: Any, topic: str) -> None:
    """When a client serving a service is killed, its service leaves the ROS graph."""
    peer.request("advertise_service", service=topic, type="std_srvs/srv/SetBool", handler="setbool")

    def listed() -> bool:
        return topic in {name for name, _types in node.get_service_names_and_types()}

    wait_until(listed, DEADLINE, f"{topic} in the ROS graph")
    assert peer.proc is not None
    peer.proc.kill()
    peer.proc.wait(DEADLINE)
    wait_until(lambda: not listed(), DEADLINE, f"{topic} to leave the graph after the kill")


def failing_handler(peer: PeerProcess, node: Any, topic: str) -> None:
    """When the client's service handler reports failure, the rclpy caller gets no invented answer."""
    from std_srvs.srv import SetBool

    peer.request("advertise_service", service=topic, type="std_srvs/srv/SetBool", handler="fail")
    client = node.create_client(SetBool, topic)
    try:
        assert client.wait_for_service(timeout_sec=DEADLINE), f"{topic} never appeared"
        future = client.call_async(SetBool.Request(data=True))
        peer.wait_event(lambda e: e.get("event") == "request" and e.get("service") == topic,
                        DEADLINE, "the request")
        # The peer answered result false before it handles this command, and the bridge
        # handles the peer's ops in order: the failure has been dealt with by now.
        peer.request("get_topic_type", topic="/rosout")
        assert not future.done()  # a ROS service cannot send an error; no default either
    finally:
        node.destroy_client(client)


def call_timeout(peer: PeerProcess, node: Any, topic: str) -> None:
    """A call with roslib's timeout argument fails promptly when the rclpy service is too slow."""
    from std_srvs.srv import SetBool

    release, answered = threading.Event(), threading.Event()

    def slow(request: Any, response: Any) -> Any:
        release.wait(DEADLINE)  # held until the test has seen the client give up
        response.success = True
        answered.set()
        return response

    node.create_service(SetBool, topic, slow)
    wait_until(lambda: topic in peer.request("get_services"), DEADLINE, f"{topic} in get_services")
    try:
        value = peer.request("call", service=topic, args={"data": True}, call_timeout=0.5)
    except PeerError as exc:
        assert "time" in str(exc).lower(), f"the failure does not say it timed out: {exc}"
    else:
        raise AssertionError(f"the slow call succeeded: {value!r}")
    finally:
        release.set()
        answered.wait(DEADLINE)


# -- refused arguments -------------------------------------------------------------------------


def call_bad_args(peer: PeerProcess, node: Any, topic: str) -> None:
    """A call with a wrong value type or an unknown field fails with the field's name (rosapi too)."""
    from std_srvs.srv import SetBool

    node.create_service(SetBool, topic, lambda _req, resp: resp)
    wait_until(lambda: topic in peer.request("get_services"), DEADLINE, f"{topic} in get_services")
    cases = (
        (topic, {"data": "yes"}, "data"),
        (topic, {"dta": True}, "dta"),
        ("/rosapi/topic_type", {"topik": topic}, "topik"),  # the bridge's own services too
    )
    for service, args, field in cases:
        try:
            value = peer.request("call", service=service, args=args)
        except PeerError as exc:
            assert field in str(exc), f"the error does not name {field!r}: {exc}"
        else:
            raise AssertionError(f"a call with {args} succeeded: {value!r}")


# -- serving asynchronously --------------------------------------------------------------------


def serve_async(peer: PeerProcess, node: Any, topic: str) -> None:
    """A service served with roslib's advertiseAsync answers an rclpy caller."""
    from mult_msgs.srv import MultFloats

    peer.request("advertise_service", service=topic, type="mult_msgs/srv/MultFloats",
                 handler="mult", **{"async": True})
    response = _call_from_ros(node, MultFloats, topic, MultFloats.Request(x=-2.0, y=0.25))
    assert response.result == -0.5


# -- concurrent calls --------------------------------------------------------------------------


def concurrent_calls(peer: PeerProcess, node: Any, topic: str) -> None:
    """While one call waits on a slow rclpy service, another call on the same connection completes."""
    from std_srvs.srv import SetBool

    release = threading.Event()

    def slow(request: Any, response: Any) -> Any:
        release.wait(DEADLINE)
        response.success, response.message = True, "slow done"
        return response

    def fast(request: Any, response: Any) -> Any:
        response.success, response.message = True, "fast done"
        return response

    group = _module("rclpy.callback_groups").ReentrantCallbackGroup()
    node.create_service(SetBool, topic + "_slow", slow, callback_group=group)
    node.create_service(SetBool, topic + "_fast", fast, callback_group=group)

    def both_listed() -> bool:
        services = peer.request("get_services")
        return topic + "_slow" in services and topic + "_fast" in services

    wait_until(both_listed, DEADLINE, "both services in get_services")
    try:
        slow_seq = peer.send("call", service=topic + "_slow", args={"data": True})
        answer = peer.request("call", service=topic + "_fast", args={"data": True})
        assert answer == {"success": True, "message": "fast done"}
        assert slow_seq not in peer.replies, "the slow call finished before it was released"
    finally:
        release.set()
    slow_reply = peer.reply(slow_seq, DEADLINE)
    assert slow_reply["ok"] and slow_reply["value"]["message"] == "slow done", slow_reply


# -- relative names ----------------------------------------------------------------------------


def serve_relative_name(peer: PeerProcess, node: Any, topic: str) -> None:
    """A service the client advertises without the leading slash answers ROS callers."""
    from std_srvs.srv import SetBool

    peer.request("advertise_service", service=topic.lstrip("/"), type="std_srvs/srv/SetBool",
                 handler="setbool")
    client = node.create_client(SetBool, topic)
    try:
        assert client.wait_for_service(timeout_sec=DEADLINE), f"{topic} never appeared"
        done = threading.Event()
        future = client.call_async(SetBool.Request(data=True))
        future.add_done_callback(lambda _f: done.set())
        # The server is matched already, so the request reaches the client's handler at
        # once, or never (the bridge would answer the caller by itself after its timeout).
        peer.wait_event(lambda e: e.get("event") == "request", 5.0,
                        "the request in the client's service handler")
        assert done.wait(DEADLINE), f"no response from {topic}"
        response = future.result()
    finally:
        node.destroy_client(client)
    assert response.success is True
    assert response.message.endswith("got data=True")
