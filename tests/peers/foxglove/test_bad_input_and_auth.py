"""The stock Foxglove client's bad frames and bad CDR, and what a bridge with an auth file allows it."""

from __future__ import annotations

import json
import queue
import time
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import BridgeProcess, wait_until
from tests.peers import scenarios
from tests.peers.foxglove.support import (
    DEADLINE,
    _errors,
    _publish_until_seen,
    _schema,
    _serving_on,
    _wait_error,
)
from tests.peers.peer import PeerProcess, foxglove_peer
from tests.security.support import WatcherAuth

# -- bad input -----------------------------------------------------------------------------------


def test_bad_frames_get_status_errors(fox: PeerProcess, ros_node: Any, topic: str) -> None:
    """Malformed JSON, an unknown op, bad binary opcodes, unknown channel, subscription and
    service ids: each answered with a status error naming it; the connection serves on."""
    cases: list[tuple[str, dict[str, Any], str]] = [
        ("send_text", {"text": "{not json"}, "malformed JSON at line 1 column 2"),
        ("send_text", {"text": '{"op": "frobnicate"}'}, "unknown op 'frobnicate'"),
        ("send_text", {"text": '{"op": "subscribe", "subscriptions": [{"id": "x"}]}'},
         "subscribe.subscriptions[0].id"),
        ("send_binary", {"hex": "07aabb"}, "unknown binary opcode 0x07"),
        ("send_binary", {"hex": "01aa"}, "too short"),
        ("send_text", {"text": '{"op": "subscribe", "subscriptions": [{"id": 9, '
                               '"channelId": 999999}]}'}, "no channel 999999"),
        ("send_text", {"text": '{"op": "unsubscribe", "subscriptionIds": [424242]}'},
         "no subscription 424242"),
        ("send_binary", {"hex": "01" + "39300000" + "00010000"}, "no client channel 12345"),
    ]
    for cmd, params, part in cases:
        fox.request(cmd, timeout=DEADLINE, **params)
        _wait_error(fox, part)
    with pytest.raises(Exception, match="no service 777"):
        fox.request("call_service_id", service_id=777, hex="00010000")
    _serving_on(fox, ros_node, topic)


def test_deep_nesting_is_a_status_error(fox: PeerProcess, bridge: BridgeProcess,
                                        ros_node: Any, topic: str) -> None:
    """JSON nested 5,000 deep, as a frame or as a json client channel's message, is answered
    with a status error in rosbridge's words ("nested too deeply"); no traceback is logged,
    and that client and another one serve on."""
    other = foxglove_peer(bridge.url, bridge)
    try:
        start = len(bridge.lines)
        deep = "[" * 5000 + "]" * 5000
        fox.request("send_text", text='{"op": "subscribe", "subscriptions": ' + deep + "}")
        assert _wait_error(fox, "nested too deeply") == "malformed JSON: nested too deeply"
        fox.request("advertise", topic=topic, schemaName="std_msgs/msg/String", encoding="json")
        fox.request("publish_bytes", topic=topic, hex=deep.encode().hex())
        _wait_error(fox, f"message data on {topic} (std_msgs/msg/String, json): not published: "
                         "malformed JSON: nested too deeply")
        assert not [line for line in bridge.lines[start:] if "Traceback" in line]
        _serving_on(fox, ros_node, topic)
        _serving_on(other, ros_node, topic + "_other")
    finally:
        other.close()


def test_bad_cdr_is_not_published(fox: PeerProcess, ros_node: Any, topic: str) -> None:
    """Truncated CDR on a client channel is refused with a status error; rclpy gets nothing."""
    from std_msgs.msg import String

    inbox: queue.Queue[Any] = queue.Queue()
    ros_node.create_subscription(String, topic, inbox.put, 10)
    fox.request("advertise", topic=topic, schemaName="std_msgs/msg/String",
                schema=_schema("std_msgs/msg/String"))
    fox.request("publish_bytes", topic=topic, hex="00010000ff000000")  # a 255-byte string: cut
    _wait_error(fox, f"message data on {topic}")
    deadline = time.monotonic() + DEADLINE
    while inbox.empty() and time.monotonic() < deadline:  # good ones go through (once matched)
        fox.request("publish", topic=topic, msg={"data": "good"})
        time.sleep(scenarios.ATTEMPT)
    assert {m.data for m in list(inbox.queue)} == {"good"}


def test_token_in_query_string(secured: tuple[BridgeProcess, Any], ros_node: Any,
                               topic: str) -> None:
    """A token in ?token= opens a Foxglove session; without one the bridge closes it (1008)."""
    bridge, auth = secured
    with pytest.raises(AssertionError, match=r"could not connect.*1008"):
        foxglove_peer(bridge.url, bridge)
    peer = foxglove_peer(f"{bridge.url}/?token={auth.tokens['tester']}", bridge)
    try:
        assert peer.info["protocol"] == "foxglove.websocket.v1"
    finally:
        peer.close()
    assert auth.tokens["tester"] not in "\n".join(bridge.lines)


def test_forbidden_publish_and_oversize(secured: tuple[BridgeProcess, Any], ros_node: Any,
                                        topic: str) -> None:
    """A publish the role forbids and a client message over the size limit each get a status
    error; nothing reaches ROS; the client serves on."""
    from std_msgs.msg import String

    bridge, auth = secured
    peer = foxglove_peer(f"{bridge.url}/?token={auth.tokens['tester']}", bridge)
    try:
        inbox: queue.Queue[Any] = queue.Queue()
        ros_node.create_subscription(String, "/op/forbidden", inbox.put, 10)
        peer.request("advertise", topic="/op/forbidden", schemaName="std_msgs/msg/String",
                     schema=_schema("std_msgs/msg/String"))
        _wait_error(peer, "forbidden: role tester may not publish on /op/forbidden")
        peer.request("publish_bytes", channel=1, hex="00010000030000006869000000")
        _wait_error(peer, "no client channel")
        peer.request("advertise", topic="/op" + topic, schemaName="std_msgs/msg/String",
                     schema=_schema("std_msgs/msg/String"))
        peer.request("send_big", channel=2, size=100_000)
        _wait_error(peer, "over this bridge's limit of 65536 bytes")
        assert inbox.empty()
        _serving_on(peer, ros_node, "/op" + topic)
    finally:
        peer.close()


def test_role_decides_what_is_shown(secured: tuple[BridgeProcess, Any], ros_node: Any,
                                    topic: str) -> None:
    """A role that may subscribe only to /probe/* is shown only those channels, and its
    subscribe to another channel's id (learnt elsewhere) is refused as forbidden."""
    from std_msgs.msg import String

    bridge, auth = secured
    ros_node.create_publisher(String, "/probe" + topic, 10)
    ros_node.create_publisher(String, topic, 10)
    tester = foxglove_peer(f"{bridge.url}/?token={auth.tokens['tester']}", bridge)
    try:
        tester.request("wait_channel", topic="/probe" + topic, timeout_ms=int(DEADLINE * 1000))
        other = tester.request("wait_channel", topic=topic, timeout_ms=int(DEADLINE * 1000))
    finally:
        tester.close()
    prober = foxglove_peer(f"{bridge.url}/?token={auth.tokens['prober']}", bridge)
    try:
        first = prober.wait_event(lambda e: e.get("event") == "advertise", DEADLINE, "advertise")
        shown = {c["topic"] for c in first["channels"]}
        assert "/probe" + topic in shown and topic not in shown
        assert all(t.startswith("/probe/") for t in shown), shown
        prober.request("send_text", text=json.dumps(
            {"op": "subscribe", "subscriptions": [{"id": 1, "channelId": other["id"]}]}))
        _wait_error(prober, f"{topic}: forbidden: role prober may not subscribe")
    finally:
        prober.close()


def test_publisher_limit(secured: tuple[BridgeProcess, Any], topic: str) -> None:
    """--max-publishers holds for Foxglove client channels: the third topic is refused."""
    bridge, auth = secured
    peer = foxglove_peer(f"{bridge.url}/?token={auth.tokens['tester']}", bridge)
    try:
        for n in range(3):
            peer.request("advertise", topic=f"/op{topic}_{n}", schemaName="std_msgs/msg/String",
                         schema=_schema("std_msgs/msg/String"))
        _wait_error(peer, f"/op{topic}_2): too many publishers on this connection (at most 2)")
        assert len([m for m in _errors(peer) if "too many publishers" in m]) == 1
    finally:
        peer.close()


def test_json_publish_and_bad_service_request(fox: PeerProcess, ros_node: Any,
                                              topic: str) -> None:
    """A client channel in json encoding reaches rclpy; a service request whose CDR does not
    decode gets a serviceCallFailure naming the type, and nothing is called."""
    from std_msgs.msg import String
    from std_srvs.srv import SetBool

    inbox: queue.Queue[Any] = queue.Queue()
    ros_node.create_subscription(String, topic, inbox.put, 10)
    fox.request("advertise", topic=topic, schemaName="std_msgs/msg/String", encoding="json")
    deadline = time.monotonic() + DEADLINE
    while inbox.empty() and time.monotonic() < deadline:
        fox.request("publish", topic=topic, msg={"data": "as json"})
        time.sleep(scenarios.ATTEMPT)  # until the bridge's publisher is matched (DDS)
    assert inbox.get_nowait().data == "as json"
    calls: list[Any] = []

    def answer(request: Any, response: Any) -> Any:
        calls.append(request)
        return response

    ros_node.create_service(SetBool, topic + "_srv", answer)
    service = fox.request("service", service=topic + "_srv", timeout_ms=int(DEADLINE * 1000))
    with pytest.raises(Exception, match="does not decode as std_srvs/srv/SetBool"):
        fox.request("call_service_id", service_id=service["id"], hex="0001")
    assert calls == []


def test_sighup_ends_what_the_role_no_longer_allows(tmp_path: Path, ros_node: Any,
                                                    topic: str) -> None:
    """After SIGHUP narrows the role, a Foxglove client's live subscription it no longer
    allows ends: the client hears why, and the bridge's ROS subscription goes."""
    from std_msgs.msg import String

    auth = WatcherAuth(tmp_path)
    bridge = BridgeProcess(args=["--auth-file", str(auth.path)]).start()
    try:
        pub = ros_node.create_publisher(String, "/secret" + topic, 10)
        peer = foxglove_peer(f"{bridge.url}/?token={auth.token}", bridge)
        try:
            peer.request("subscribe", topic="/secret" + topic, timeout_ms=int(DEADLINE * 1000))
            _publish_until_seen(peer, pub, "/secret" + topic, String(data="before"))
            line = auth.narrow(bridge)
            assert "1 grant(s) the new roles no longer allow ended" in line
            _wait_error(peer, f"/secret{topic} ended: role watcher may not subscribe")
            wait_until(lambda: pub.get_subscription_count() == 0, DEADLINE,
                       "the bridge's ROS subscription to end")
        finally:
            peer.close()
    finally:
        bridge.stop()
