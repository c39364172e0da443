"""No valid Foxglove publish costs the bridge more than a small multiple of its size, or stalls
another client (issue 53, finding 3), against a real bridge process.

A stock Foxglove client (``@foxglove/ws-protocol``) whose role may publish on ``/op/*``
advertises ``test_msgs/msg/UnboundedSequences`` as ``cdr`` and sends 4 MiB of empty structs
(``constants_values``: ~290 MB decoded), valid, then the same cut short at its tail. Each
gets a status error naming the field and the decode budget; the bridge's peak RSS rises by
less than 20 times the message plus 64 MiB, and another client's websocket pings are
answered within PING_BOUND all along. Large valid messages (4 MiB of strings, decoded off
the loop) and small ones sent between them reach a ROS subscriber in the order sent.
"""

from __future__ import annotations

import contextlib
import struct
import threading
import time
from pathlib import Path
from typing import Any

from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from bridge_server.foxglove.hub import foxglove_schema
from msgs import cdr, dynamic
from msgs.test_msgs.msg import Constants, UnboundedSequences
from tests.helpers import BridgeProcess, peak_rss
from tests.peers import scenarios
from tests.peers.peer import foxglove_peer
from tests.security.support import make_auth_file

MIB = 4
"""Size of the large messages, in MiB."""
PING_BOUND = 1.0
"""Seconds another client's ping may wait for its pong, at most (a few ms unloaded)."""
PER_BYTE = 20
"""Peak RSS the bridge may add per byte of the message (the issue's target)."""
SLACK = 64 * 2**20
"""And besides, whatever the message."""
DEADLINE = scenarios.DEADLINE
SCHEMA = "test_msgs/msg/UnboundedSequences"
_AT = 4 + 4 * list(UnboundedSequences._fields_and_types).index("constants_values")


def empties(count: int) -> bytes:
    """A valid UnboundedSequences of ``count`` empty ``constants_values`` (one placeholder
    byte each) and defaults elsewhere."""
    base = cdr.encode(UnboundedSequences(constants_values=[Constants()] * (count % 8)))
    return base[:_AT] + struct.pack("<I", count) + bytes(count - count % 8) + base[_AT + 4:]


class Pinger:
    """Another client of the bridge (rosbridge protocol, in a thread) pinging it every 50 ms:
    how long each pong took."""

    def __init__(self, url: str) -> None:
        self.opened = contextlib.ExitStack()
        self.ws = self.opened.enter_context(connect(url, open_timeout=DEADLINE))
        self.waits: list[float] = []
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while not self.stop.wait(0.05):
            start = time.monotonic()
            try:
                pong = self.ws.ping()
            except ConnectionClosed:
                return
            answered = pong.wait(30)
            self.waits.append(time.monotonic() - start if answered else 30.0)

    def worst_since(self, count: int) -> float:
        """The longest wait of the pings after the first ``count``."""
        self.stop.set()
        self.thread.join(35)
        return max(self.waits[count:])

    def close(self) -> None:
        self.stop.set()
        self.thread.join(35)
        self.opened.close()


def test_empty_struct_bombs_are_refused_and_nobody_waits(
    make_bridge: Any, ros_node: Any, topic: str, tmp_path: Path,
) -> None:
    """4 MiB of empty structs, whole and cut short at its tail: each gets a status error
    naming the field and the budget, the bridge's peak RSS rises by less than 20x the message
    + 64 MiB, and another client's pings are answered within PING_BOUND all along."""
    auth = make_auth_file(tmp_path)
    bridge: BridgeProcess = make_bridge("--auth-file", str(auth.path))
    assert bridge.proc is not None
    bomb_topic = "/op" + topic
    attacker = foxglove_peer(f"{bridge.url}/?token={auth.tokens['tester']}", bridge)
    pinger = Pinger(f"{bridge.url}/?token={auth.tokens['viewer']}")
    try:
        attacker.request("advertise", topic=bomb_topic, schemaName=SCHEMA,
                         schema=foxglove_schema(dynamic.full_text(SCHEMA)))
        whole = empties(MIB * 2**20)
        cut = whole[:-4]  # fails only at its tail (alignment_check)
        while len(pinger.waits) < 5:  # the pinger's first pongs: it is connected and served
            assert pinger.thread.is_alive(), "the pinger stopped"
            time.sleep(0.05)
        pinged, before = len(pinger.waits), peak_rss(bridge.proc.pid)
        errors = []
        for data in (whole, cut):
            attacker.request("publish_bytes", topic=bomb_topic, hex=data.hex(), timeout=60)
            errors.append(attacker.wait_event(lambda e: e.get("event") == "status"
                                              and e.get("level") == 2, DEADLINE,
                                              "a status error")["message"])
        time.sleep(0.5)  # pings while the bridge settles after the last one
        rise = peak_rss(bridge.proc.pid) - before
        worst = pinger.worst_since(pinged)
        print(f"foxglove bomb of {MIB} MiB: peak RSS +{rise / 2**20:.0f} MiB, pong at most "
              f"{worst:.3f} s")
        for error in errors:
            assert error.startswith(
                f"message data on {bomb_topic} ({SCHEMA}, cdr): not published: {SCHEMA}: "
                "cannot decode field 'constants_values' from CDR: its "), error
            assert "over the decode budget" in error and "--decode-budget-per-byte" in error
        assert rise < PER_BYTE * len(whole) + SLACK, (
            f"the bridge's peak RSS rose by {rise / 2**20:.0f} MiB")
        assert worst < PING_BOUND, f"a ping waited {worst:.2f} s for its pong"
        assert attacker.request("is_open") is True
    finally:
        pinger.close()
        attacker.close()


def test_large_messages_are_published_in_order(
    make_bridge: Any, ros_node: Any, topic: str, tmp_path: Path,
) -> None:
    """Large valid messages (4 MiB of one-character strings, decoded off the loop) and small
    ones between them reach a ROS subscriber in the order the client sent them."""
    auth = make_auth_file(tmp_path)
    bridge: BridgeProcess = make_bridge("--auth-file", str(auth.path))
    pub_topic = "/op" + topic
    got: list[tuple[int, int]] = []
    heard = threading.Condition()

    def on_message(msg: Any) -> None:
        with heard:
            got.append((len(msg.string_values), msg.alignment_check))
            heard.notify_all()

    from test_msgs.msg import UnboundedSequences as RosUnbounded

    ros_node.create_subscription(RosUnbounded, pub_topic, on_message, 10)
    client = foxglove_peer(f"{bridge.url}/?token={auth.tokens['tester']}", bridge)
    try:
        client.request("advertise", topic=pub_topic, schemaName=SCHEMA,
                       schema=foxglove_schema(dynamic.full_text(SCHEMA)))
        deadline = time.monotonic() + DEADLINE
        while not got:  # until the bridge's publisher reached the subscriber
            assert time.monotonic() < deadline, "the subscriber never heard the bridge"
            client.request("publish_bytes", topic=pub_topic,
                           hex=cdr.encode(UnboundedSequences(alignment_check=-1)).hex())
            with heard:
                heard.wait_for(lambda: bool(got), 0.5)
        count = MIB * 2**20 // 8  # 'a' and its NUL, its length and 2 bytes of padding each
        large = cdr.encode(UnboundedSequences(string_values=["a"] * count, alignment_check=1))
        small = cdr.encode(UnboundedSequences(alignment_check=2))
        for data in (large, small, large, small):
            client.request("publish_bytes", topic=pub_topic, hex=data.hex(), timeout=60)

        def sent() -> list[tuple[int, int]]:  # the warm-up's late ones aside
            return [one for one in got if one[1] != -1]

        with heard:
            assert heard.wait_for(lambda: len(sent()) >= 4, DEADLINE), got
        assert sent() == [(count, 1), (0, 2), (count, 1), (0, 2)]
    finally:
        client.close()
