"""Helpers shared by the stock Foxglove client tests (tests/peers/foxglove/test_*.py).

What the client saw (messages, status errors, graph updates), waiting for it, parameter
commands, a client with a role's token, the bridge's status page, and a bridge whose auth file a
test rewrites and reloads.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from bridge_server.foxglove.hub import foxglove_schema
from msgs import dynamic
from tests.helpers import BridgeProcess
from tests.peers import scenarios
from tests.peers.peer import PeerProcess, foxglove_peer
from tests.peers.scenarios.support import until_message_event

DEADLINE = scenarios.DEADLINE


def _schema(type_name: str) -> str:
    """The definition text of a type as Foxglove clients take it."""
    return foxglove_schema(dynamic.full_text(type_name))


def _messages(peer: PeerProcess, topic: str) -> list[dict[str, Any]]:
    return [e for e in peer.new_events() if e.get("event") == "message" and e["topic"] == topic]


def _errors(peer: PeerProcess) -> list[str]:
    return [e["message"] for e in peer.new_events()
            if e.get("event") == "status" and e.get("level") == 2]


def _wait_error(peer: PeerProcess, part: str) -> str:
    event = peer.wait_event(lambda e: e.get("event") == "status" and e.get("level") == 2
                            and part in e.get("message", ""), DEADLINE, f"status error '{part}'")
    return str(event["message"])


def _publish_until_seen(peer: PeerProcess, pub: Any, topic: str, msg: Any) -> dict[str, Any]:
    """Publish from rclpy until the client has a message on ``topic`` (DDS matching)."""
    return until_message_event(peer, lambda: pub.publish(msg), topic)


def _serving_on(peer: PeerProcess, ros_node: Any, topic: str) -> None:
    """The connection is open and the bridge still serves it: a new subscription works."""
    from std_msgs.msg import String

    assert peer.request("is_open") is True
    pub = ros_node.create_publisher(String, topic + "_alive", 10)
    peer.request("subscribe", topic=topic + "_alive", timeout_ms=int(DEADLINE * 1000))
    assert _publish_until_seen(peer, pub, topic + "_alive", String(data="alive"))["msg"] == {
        "data": "alive"}


def _parameter_values(fox: PeerProcess, request_id: str, cmd: str, **params: Any
                      ) -> list[dict[str, Any]]:
    """Send a parameter command with ``request_id``; the ``parameterValues`` answering it."""
    fox.request(cmd, id=request_id, **params)
    event = fox.wait_event(lambda e: e.get("event") == "parameterValues"
                           and e["id"] == request_id, DEADLINE, f"parameterValues {request_id}")
    found: list[dict[str, Any]] = event["parameters"]
    return found


def _update(fox: PeerProcess, entry: dict[str, Any], timeout: float = DEADLINE) -> None:
    """Wait for a parameter update event (no id) that holds ``entry``."""
    fox.wait_event(lambda e: e.get("event") == "parameterValues" and e["id"] is None
                   and entry in e["parameters"], timeout, f"an update with {entry}")


def _as(secured: tuple[BridgeProcess, Any], role: str) -> PeerProcess:
    """A Foxglove client of the ``secured`` bridge with the token of ``role``'s principal."""
    bridge, auth = secured
    return foxglove_peer(f"{bridge.url}/?token={auth.tokens[role]}", bridge)


def _all_sent(peer: PeerProcess) -> list[dict[str, Any]]:
    """The client's events once it has the answer to a frame sent now: all that the bridge
    sent it before that frame (it answers each client's frames in order)."""
    peer.request("send_text", text='{"op": "barrier"}')
    _wait_error(peer, "unknown op 'barrier'")
    return peer.new_events()


def _graph_names(events: list[dict[str, Any]]) -> set[str]:
    """Every topic, service and node named by the connection graph updates among ``events``."""
    names: set[str] = set()
    for event in events:
        if event.get("event") != "connectionGraphUpdate":
            continue
        update = event["update"]
        for key, ids in (("publishedTopics", "publisherIds"), ("subscribedTopics",
                                                               "subscriberIds"),
                         ("advertisedServices", "providerIds")):
            for entry in update[key]:
                names.add(entry["name"])
                names.update(entry[ids])
        names.update(update["removedTopics"], update["removedServices"])
    return names


def _rosbridge_refusal(bridge: BridgeProcess, token: str, service: str) -> str:
    """The status error a rosbridge client with ``token`` gets for calling ``service``."""
    from websockets.sync.client import connect

    with connect(bridge.url, additional_headers={"Authorization": f"Bearer {token}"},
                 open_timeout=DEADLINE) as ws:
        ws.send(json.dumps({"op": "call_service", "service": service, "id": "r"}))
        while True:
            reply = json.loads(ws.recv(DEADLINE))
            if reply.get("op") == "status" and reply.get("level") == "error":
                return str(reply["msg"])


def _published_by(topic: str, node: str) -> Any:
    """A predicate: a graph update in which ``node`` publishes ``topic``."""
    return lambda e: e.get("event") == "connectionGraphUpdate" and any(
        t["name"] == topic and node in t["publisherIds"]
        for t in e["update"]["publishedTopics"])


def _status(bridge: BridgeProcess) -> Any:
    import urllib.request

    with urllib.request.urlopen(bridge.url.replace("ws:", "http:") + "/status.json",
                                timeout=DEADLINE) as response:
        return json.load(response)


def _bridge_received(bridge: BridgeProcess, topic: str, count: int) -> bool:
    """Whether the bridge has received ``count`` messages of ``topic`` from ROS."""
    return bool(_status(bridge)["topics"][topic]["ros_received"] >= count)


def _graph_topics(bridge: BridgeProcess) -> list[str]:
    """The topics the bridge's ROS side lists (asked over rosbridge: /rosapi/topics)."""
    from websockets.sync.client import connect

    with connect(bridge.url, open_timeout=DEADLINE) as ws:
        ws.send(json.dumps({"op": "call_service", "service": "/rosapi/topics", "id": "t"}))
        while True:
            reply = json.loads(ws.recv(DEADLINE))
            if reply.get("op") == "service_response":
                return list(reply["values"]["topics"])


class _ReloadedRoles:
    """A bridge whose auth file a test rewrites and reloads with SIGHUP: role ``watcher`` (whose
    table the test writes) for principal ``dora``, role ``all`` for ``root``."""

    def __init__(self, directory: Path, watcher: str) -> None:
        from rosbridge_core.security.auth import hash_token, new_token

        self.tokens = {"dora": new_token(), "root": new_token()}
        self.path = directory / "auth.toml"
        self._principals = "".join(
            f'\n[principals.{n}]\nrole = "{"all" if n == "root" else "watcher"}"\n'
            f'token_hash = "{hash_token(t)}"\n' for n, t in self.tokens.items())
        self.write(watcher)
        self.bridge = BridgeProcess(args=["--auth-file", str(self.path)]).start()
        self.peers: list[PeerProcess] = []

    def write(self, watcher: str) -> None:
        """Give role ``watcher`` the table ``watcher`` (TOML lines) in the file."""
        self.path.write_text('[roles.all]\nall = ["*"]\n[roles.watcher]\n' + watcher
                             + self._principals)

    def reload(self, watcher: str) -> str:
        """Write ``watcher``'s table, send the bridge SIGHUP; its reload log line."""
        import signal

        self.write(watcher)
        start = len(self.bridge.lines)
        assert self.bridge.proc is not None
        self.bridge.proc.send_signal(signal.SIGHUP)
        return self.bridge.wait_for_line(r"reloaded the auth file", start=start)

    def connect(self, name: str) -> PeerProcess:
        """A Foxglove client with the token of ``name`` (closed by :meth:`close`)."""
        self.peers.append(foxglove_peer(f"{self.bridge.url}/?token={self.tokens[name]}",
                                        self.bridge))
        return self.peers[-1]

    def close(self) -> None:
        """Close the clients and stop the bridge."""
        for peer in self.peers:
            peer.close()
        self.bridge.stop()
