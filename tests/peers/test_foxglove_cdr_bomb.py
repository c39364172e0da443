"""The CDR bomb of issue 39 over Foxglove, against a real bridge process: a stock Foxglove
client (``@foxglove/ws-protocol``) whose role may publish on ``/op/*`` advertises a topic as
``cdr`` with schema ``test_msgs/msg/UnboundedSequences`` and sends the 73 bytes whose
``constants_values`` (``test_msgs/Constants`` has no fields) claims millions of elements. It
gets a status error naming the field; the bridge's peak RSS stays within RSS_BOUND; a viewer
on another topic keeps getting its messages."""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Any

from bridge_server.foxglove.hub import foxglove_schema
from msgs import dynamic
from tests.helpers import BridgeProcess, peak_rss
from tests.msgs.test_cdr_bounds import bomb
from tests.peers import scenarios
from tests.peers.peer import foxglove_peer
from tests.security.support import make_auth_file

COUNT = 3_000_000
"""Empty messages the bomb claims: before the fix the bridge built a dict for each (~220 MB
here; the issue's 3x10^7 took it to 1.9 GB and stalled it 6.7 s)."""
RSS_BOUND = 64 * 2**20
"""How far the bridge's peak RSS may rise while it handles the bomb."""
DEADLINE = scenarios.DEADLINE


def test_cdr_bomb_gets_an_error_and_costs_the_bridge_no_memory(
    make_bridge: Any, ros_node: Any, topic: str, tmp_path: Path,
) -> None:
    """A 73-byte CDR message claiming 3x10^6 empty messages gets a status error naming the
    field, the bridge's peak RSS rises by less than RSS_BOUND, and a viewer keeps receiving."""
    from std_msgs.msg import Int32

    auth = make_auth_file(tmp_path)
    bridge: BridgeProcess = make_bridge("--auth-file", str(auth.path))
    assert bridge.proc is not None
    beat_topic, bomb_topic = topic + "_beat", "/op" + topic
    beats = itertools.count()
    sent = [0]
    pub = ros_node.create_publisher(Int32, beat_topic, 10)

    def beat() -> None:
        sent[0] = next(beats)
        pub.publish(Int32(data=sent[0]))

    timer = ros_node.create_timer(0.02, beat)
    viewer = foxglove_peer(f"{bridge.url}/?token={auth.tokens['viewer']}", bridge)
    attacker = foxglove_peer(f"{bridge.url}/?token={auth.tokens['tester']}", bridge)
    try:
        viewer.request("subscribe", topic=beat_topic, timeout_ms=int(DEADLINE * 1000))
        viewer.wait_event(lambda e: e.get("event") == "message" and e["topic"] == beat_topic,
                          DEADLINE, "the viewer's first message")
        attacker.request("advertise", topic=bomb_topic,
                         schemaName="test_msgs/msg/UnboundedSequences",
                         schema=foxglove_schema(dynamic.full_text(
                             "test_msgs/msg/UnboundedSequences")))
        data = bomb(COUNT)
        assert len(data) == 73
        peak_before = peak_rss(bridge.proc.pid)
        attacker.request("publish_bytes", topic=bomb_topic, hex=data.hex())
        error = attacker.wait_event(lambda e: e.get("event") == "status"
                                    and e.get("level") == 2, DEADLINE, "a status error")
        assert error["message"] == (
            f"message data on {bomb_topic} (test_msgs/msg/UnboundedSequences, cdr): not "
            "published: test_msgs/msg/UnboundedSequences: cannot decode field "
            f"'constants_values' from CDR: claims {COUNT} elements of at least 1 byte each, "
            "but 5 bytes are left")
        rise = peak_rss(bridge.proc.pid) - peak_before
        assert rise < RSS_BOUND, f"the bridge's peak RSS rose by {rise / 2**20:.0f} MiB"
        after = sent[0]
        viewer.wait_event(lambda e: e.get("event") == "message" and e["topic"] == beat_topic
                          and e["msg"]["data"] > after, DEADLINE, "a message sent after the bomb")
        assert attacker.request("is_open") is True
    finally:
        ros_node.destroy_timer(timer)
        viewer.close()
        attacker.close()
