"""Scenarios between two stock clients (topics, services, actions, latched messages, failures),
and the bridge restarting under a connected client.
"""

from __future__ import annotations

from typing import Any

from tests.helpers import wait_until
from tests.peers.peer import PeerError, PeerProcess
from tests.peers.scenarios.support import (
    ATTEMPT,
    DEADLINE,
    _call_from_ros,
    _call_new_service,
    _latched_qos,
    _ros_publish_until_delivered,
)

# -- between two stock clients ----------------------------------------------------------------


def client_to_client_topic(
    sender: PeerProcess, receiver: PeerProcess, node: Any, topic: str
) -> None:
    """What one stock client publishes, another stock client on the same bridge receives."""
    type_name = "std_msgs/String"
    receiver.request("subscribe", topic=topic, type=type_name)
    wait_until(lambda: node.count_subscribers(topic) >= 1, DEADLINE, f"bridge subscriber on {topic}")
    sender.request("advertise", topic=topic, type=type_name)
    wait_until(lambda: node.count_publishers(topic) >= 1, DEADLINE, f"bridge publisher on {topic}")
    text = f"from {sender.name} to {receiver.name}"
    for _ in range(int(DEADLINE / ATTEMPT)):
        sender.request("publish", topic=topic, type=type_name, msg={"data": text})
        try:
            got = receiver.wait_event(
                lambda e: e.get("event") == "message" and e.get("topic") == topic, ATTEMPT
            )
        except AssertionError:
            continue
        assert got["msg"] == {"data": text}
        return
    raise AssertionError(f"{receiver.name} never got {sender.name}'s message\n{receiver.diagnostics()}")


def client_to_client_service(
    server: PeerProcess, caller: PeerProcess, node: Any, topic: str
) -> None:
    """A service one stock client serves answers another stock client's call."""
    server.request("advertise_service", service=topic, type="mult_msgs/srv/MultFloats", handler="mult")

    def listed() -> bool:
        return topic in {name for name, _types in node.get_service_names_and_types()}

    wait_until(listed, DEADLINE, f"{topic} in the ROS graph")
    assert _call_new_service(caller, topic, {"x": 3.0, "y": 0.5}) == {"result": 1.5}
    assert server.wait_event(lambda e: e.get("event") == "request" and e["service"] == topic)[
        "args"
    ] == {"x": 3.0, "y": 0.5}


# -- the bridge restarting under a connected stock client; more between two clients ------


def reconnect_after_bridge_restart(peer: PeerProcess, bridge: Any, node: Any, topic: str) -> None:
    """After the bridge crashes and comes back on its port, roslibpy's own reconnection
    restores its subscription and its served service."""
    from std_msgs.msg import String
    from std_srvs.srv import SetBool

    service = topic + "_srv"
    pub = node.create_publisher(String, topic, 10)
    peer.request("subscribe", topic=topic, type="std_msgs/msg/String")
    peer.request("advertise_service", service=service, type="std_srvs/srv/SetBool",
                 handler="setbool")
    _ros_publish_until_delivered(peer, pub, topic, String(data="before"))
    bridge.kill()
    bridge.start()
    peer.begin_test()
    got = _ros_publish_until_delivered(peer, pub, topic, String(data="after"))
    assert got == {"data": "after"}
    response = _call_from_ros(node, SetBool, service, SetBool.Request(data=True))
    assert response.message == "roslibpy got data=True"


def client_to_client_action(server: PeerProcess, caller: PeerProcess, node: Any, topic: str) -> None:
    """A Fibonacci action roslib serves answers a goal another stock client sends."""
    server.request(
        "advertise_action", action=topic, type="test_msgs/action/Fibonacci", handler="fibonacci"
    )

    def listed() -> bool:
        refused = [e for e in server.new_events() if e.get("event") == "status"]
        assert not refused, f"the bridge refused advertise_action: {refused}"
        return topic in caller.request("get_action_servers")

    wait_until(listed, DEADLINE, f"{topic} in get_action_servers")
    value = caller.request(
        "send_goal", action=topic, type="test_msgs/action/Fibonacci", goal={"order": 5},
        goal_timeout=5.0, timeout=DEADLINE,
    )
    assert value["status"] == 4
    assert value["values"]["sequence"] == [0, 1, 1, 2, 3, 5]


def latched_to_second_client(first: PeerProcess, second: PeerProcess, node: Any, topic: str) -> None:
    """A latched message reaches a second client that subscribes after the first already has it."""
    from std_msgs.msg import String

    pub = node.create_publisher(String, topic, _latched_qos())
    pub.publish(String(data="the map"))
    for peer in (first, second):  # the second subscribes when the bridge already listens
        peer.request("subscribe", topic=topic, type="std_msgs/msg/String")
        got = peer.wait_event(
            lambda e: e.get("event") == "message" and e.get("topic") == topic, DEADLINE,
            f"the latched message on {topic}",
        )
        assert got["msg"] == {"data": "the map"}


def client_to_client_failure(server: PeerProcess, caller: PeerProcess, node: Any, topic: str) -> None:
    """When one client's service handler reports failure, another client's call fails too."""
    server.request("advertise_service", service=topic, type="std_srvs/srv/SetBool", handler="fail")

    def listed() -> bool:
        return topic in {name for name, _types in node.get_service_names_and_types()}

    wait_until(listed, DEADLINE, f"{topic} in the ROS graph")
    try:
        value = _call_new_service(caller, topic, {"data": True})
    except PeerError as exc:
        assert "Timeout" not in str(exc), f"the caller timed out instead of being told: {exc}"
    else:
        raise AssertionError(f"the call succeeded although the handler failed: {value!r}")
