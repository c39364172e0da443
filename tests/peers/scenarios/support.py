"""What every scenario leans on: the attempt and deadline times, publishing or calling until the
other end has it, a callback group of one's own, refusals and status errors a client saw.
"""

from __future__ import annotations

import importlib
import queue
import threading
import time
from typing import Any

from tests.helpers import send_until_heard_sync
from tests.peers.peer import PeerError, PeerProcess

#: How long one attempt waits for a message before publishing the next one
#: (messages sent before DDS matched the two ends are lost, so we resend).
ATTEMPT = 0.5
DEADLINE = 15.0


def _module(name: str) -> Any:
    """Import an rclpy module whose API is not fully typed, as Any."""
    return importlib.import_module(name)


def _own_group() -> Any:
    """A callback group for one test's rclpy action end on the module's shared node.

    rclpy leaves a callback group busy for ever when taking from an action client
    or server fails (one destroyed while the executor waits on it), so each action
    end gets a group of its own: the node's default group, which every later test
    uses, is never stuck by it.
    """
    return _module("rclpy.callback_groups").MutuallyExclusiveCallbackGroup()


def _refusal(peer: PeerProcess, topic: str) -> None:
    """Fail at once if the bridge sent an error status about ``topic`` (clients that show them)."""
    for e in peer.new_events():
        about_topic = str(e.get("id") or "").split(":")[1:2] == [topic]  # "op:topic:n"
        if e.get("event") == "status" and about_topic and e["msg"].get("level") == "error":
            raise AssertionError(f"the bridge refused a request about {topic}: {e['msg']}")


def _publish_until_received(
    peer: PeerProcess, topic: str, type_name: str, msg: dict[str, Any], inbox: queue.Queue[Any]
) -> Any:
    """Publish ``msg`` through the peer until the rclpy subscription's inbox gets one."""

    def publish() -> None:
        _refusal(peer, topic)
        peer.request("publish", topic=topic, type=type_name, msg=msg)

    try:
        return send_until_heard_sync(publish, lambda wait: inbox.get(timeout=wait),
                                     f"{peer.name}'s message on {topic}", ATTEMPT, DEADLINE)
    except AssertionError as e:
        raise AssertionError(f"rclpy {e}\n{peer.diagnostics()}") from None


def _ros_publish_until_delivered(peer: PeerProcess, pub: Any, topic: str, msg: Any) -> Any:
    """Publish ``msg`` from rclpy until the peer prints a message event for ``topic``."""

    def publish() -> None:
        _refusal(peer, topic)
        pub.publish(msg)

    return until_message_event(peer, publish, topic)["msg"]


def until_message_event(peer: PeerProcess, send: Any, topic: str) -> dict[str, Any]:
    """Call ``send`` until the peer prints a message event for ``topic``: that event."""
    try:
        event: dict[str, Any] = send_until_heard_sync(
            send, lambda wait: peer.wait_event(
                lambda e: e.get("event") == "message" and e.get("topic") == topic,
                wait, f"message on {topic}"),
            f"a message on {topic} at {peer.name}", ATTEMPT, DEADLINE)
    except AssertionError as e:
        raise AssertionError(f"{e}\n{peer.diagnostics()}") from None
    return event


def _call_new_service(peer: PeerProcess, service: str, args: dict[str, Any]) -> Any:
    """Call a service the test has just created, once the bridge has discovered it.

    The bridge waits a moment for a service it does not know yet; on a loaded
    machine discovery can take longer, and the bridge then answers "does not
    exist". That is graph discovery, so it is retried (with a deadline); any
    other failure is reported at once.
    """
    deadline = time.monotonic() + DEADLINE
    while True:
        try:
            return peer.request("call", service=service, args=args)
        except PeerError as exc:
            if "does not exist" not in str(exc) or time.monotonic() > deadline:
                raise


def _call_from_ros(node: Any, srv_type: Any, name: str, request: Any) -> Any:
    """Call service ``name`` from an rclpy client and return the response (with deadlines)."""
    client = node.create_client(srv_type, name)
    try:
        assert client.wait_for_service(timeout_sec=DEADLINE), f"{name} never appeared in the graph"
        done = threading.Event()
        future = client.call_async(request)
        future.add_done_callback(lambda _f: done.set())
        assert done.wait(DEADLINE), f"no response from {name} within {DEADLINE} s"
        return future.result()
    finally:
        node.destroy_client(client)


def _topics(value: Any) -> tuple[list[str], list[str] | None]:
    """roslibpy returns the topic list; roslib returns {topics, types}."""
    if isinstance(value, dict):
        return list(value["topics"]), list(value["types"])
    return list(value), None


def _latched_qos() -> Any:
    qos = _module("rclpy.qos")
    return qos.QoSProfile(
        depth=1,
        durability=qos.DurabilityPolicy.TRANSIENT_LOCAL,
        reliability=qos.ReliabilityPolicy.RELIABLE,
    )


def _messages(peer: PeerProcess, topic: str, handle: str, data: str) -> int:
    return sum(
        1 for e in peer.new_events()
        if e.get("event") == "message" and e.get("topic") == topic
        and e.get("handle") == handle and e["msg"].get("data") == data
    )


def _status_about(peer: PeerProcess, about: str, topic: str) -> dict[str, Any]:
    status = peer.wait_event(
        lambda e: e.get("event") == "status" and e.get("about") == about
        and topic in (e.get("id") or ""),
        DEADLINE, f"a status about {about} on {topic}",
    )["msg"]
    assert status["level"] == "error", status
    return status  # type: ignore[no-any-return]
