"""The wire contract between a robot's exporter and the relays: Zenoh keys and payloads.

Every key of a robot is under ``<robot>/``. A ROS name maps to key chunks by dropping
its leading ``/`` (``/camera/image`` of robot ``r1`` is ``r1/camera/image``), as
zenoh-bridge-ros2dds maps names under its ``namespace``. What is not topic data lives
under chunks that start with ``@``: Zenoh's verbatim chunks, which no wildcard matches
and no ROS name can spell, so ``r1/**`` is all of ``r1``'s topics and nothing else.

=======================================  ==============================================
key                                      what
=======================================  ==============================================
``<robot>/<topic>``                      one put per ROS message: its CDR bytes as they
                                         came; attachment :class:`Meta` (JSON)
``<robot>/@alive``                       liveliness token: the robot is there
``<robot>/@demand/<relay>/<topic>``      liveliness token of a relay watching ``topic``:
                                         the robot subscribes while one exists
``<robot>/@latched/<topic>``             queryable: the last message of a latched topic
``<robot>/@graph``                       :class:`Snapshot` JSON: put on change, and a
                                         queryable answering the current one
``<robot>/@call/<service>``              queryable: a service call, :class:`CallRequest`
                                         JSON in, the response dict (JSON) or an error
``<robot>/@advertise/<relay>/<latch>/``  liveliness token of a relay's publisher
``<pkg>/msg/<Name>/<topic>``             (``latch`` is ``latched`` or ``volatile``)
``<robot>/@in/<topic>``                  a client's message to publish: CDR bytes,
                                         attachment :class:`Meta` (type and latch)
=======================================  ==============================================

``docs/guides/relay.md`` describes the contract for people; where it differs from
zenoh-bridge-ros2dds it says why.
"""

from __future__ import annotations

import json
import re
from dataclasses import asdict, dataclass, field
from typing import Any

from ..interfaces import BridgeError, canonical_name
from ..security.names import check_name

__all__ = [
    "ADVERTISE",
    "ALIVE",
    "CALL",
    "DEMAND",
    "GRAPH",
    "IN",
    "LATCHED",
    "CallRequest",
    "Meta",
    "Snapshot",
    "advertise_key",
    "check_relay",
    "check_robot",
    "key_of",
    "name_of",
    "parse_advertise",
    "parse_demand",
]

ALIVE = "@alive"
DEMAND = "@demand"
LATCHED = "@latched"
GRAPH = "@graph"
CALL = "@call"
ADVERTISE = "@advertise"
IN = "@in"

_CHUNK = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*\Z")


def check_robot(robot: str) -> str:
    """``robot`` if it is a usable robot name (one key chunk: letters, digits, ``_ . -``,
    not starting with ``@``); :class:`~bridge_server.interfaces.BridgeError` naming it if
    not."""
    if not isinstance(robot, str) or not _CHUNK.match(robot) or len(robot) > 64:
        raise BridgeError(f"invalid robot name {robot!r}: one word of letters, digits, '_', "
                          "'.' and '-' (at most 64 characters), not starting with '.' or '-'")
    return robot


def check_relay(relay: str) -> str:
    """``relay`` if it is a usable relay id (one key chunk, as a robot name)."""
    if not _CHUNK.match(relay):
        raise BridgeError(f"invalid relay id {relay!r}")
    return relay


def key_of(robot: str, name: str, where: str = "") -> str:
    """The key of ROS name ``name`` (``/a/b``) of ``robot``, under ``where`` (``@in``, ...)
    if given; ``InvalidNameError`` for a name ROS would refuse."""
    check_name(name)
    return f"{robot}/{where}/{name[1:]}" if where else f"{robot}/{name[1:]}"


def name_of(key: str, skip: int) -> str:
    """The ROS name in ``key`` after its first ``skip`` chunks (``r1/@in/a/b``, 2: ``/a/b``)."""
    return "/" + key.split("/", skip)[skip]


def parse_demand(key: str) -> tuple[str, str]:
    """(relay id, topic) of a demand token's key."""
    relay = key.split("/", 3)[2]
    return relay, name_of(key, 3)


def advertise_key(robot: str, relay: str, topic: str, type_name: str, latch: bool) -> str:
    """The key of a relay's publisher token (see the module's table)."""
    pkg, kind, name = canonical_name(type_name, "msg").split("/")
    where = f"{ADVERTISE}/{relay}/{'latched' if latch else 'volatile'}/{pkg}/{kind}/{name}"
    return key_of(robot, topic, where)


def parse_advertise(key: str) -> tuple[str, str, bool, str]:
    """(relay id, topic, latch, type) of a publisher token's key."""
    parts = key.split("/", 7)
    return parts[2], "/" + parts[7], parts[3] == "latched", "/".join(parts[4:7])


@dataclass
class Meta:
    """The attachment of a message's put: its type, whether the topic is latched (transient
    local), the robot's receive time, and its place in the topic's stream (``epoch``: the
    exporter's run; ``seq``: counted per topic from 1) so a relay that also asked for the
    latched message takes each message once."""

    type: str
    latched: bool = False
    stamp_ns: int = 0
    epoch: str = ""
    seq: int = 0

    def encode(self) -> bytes:
        """As the attachment's bytes."""
        return json.dumps(asdict(self), separators=(",", ":")).encode()

    @classmethod
    def decode(cls, data: bytes | None) -> Meta:
        """From an attachment's bytes; ``BridgeError`` naming what is wrong."""
        try:
            obj = json.loads(data or b"")
            return cls(type=str(obj["type"]), latched=bool(obj.get("latched")),
                       stamp_ns=int(obj.get("stamp_ns", 0)), epoch=str(obj.get("epoch", "")),
                       seq=int(obj.get("seq", 0)))
        except (ValueError, KeyError, TypeError) as exc:
            raise BridgeError(f"a message's attachment is not a Meta object ({exc})") from None


@dataclass
class CallRequest:
    """A service call's query payload: what ``Graph.call_service`` takes, as JSON."""

    type: str | None
    args: Any
    timeout: float
    discovery_wait: float

    def encode(self) -> bytes:
        """As the query's payload."""
        return json.dumps(asdict(self), separators=(",", ":")).encode()

    @classmethod
    def decode(cls, data: bytes) -> CallRequest:
        """From a query's payload; ``BridgeError`` naming what is wrong."""
        try:
            obj = json.loads(data)
            return cls(type=obj["type"], args=obj["args"], timeout=float(obj["timeout"]),
                       discovery_wait=float(obj["discovery_wait"]))
        except (ValueError, KeyError, TypeError) as exc:
            raise BridgeError(f"a service call's payload is not a CallRequest ({exc})") from None


@dataclass
class Snapshot:
    """The robot's ROS graph as the relays see it (``@graph``).

    ``nodes`` maps ``/ns/name`` to ``{"name", "namespace", "subscribes", "publishes",
    "serves": [[service, [types]], ...]}``; ``publishers`` maps a topic to ``[[node,
    namespace, qos], ...]`` (the QoS in rosbag2's words); ``definitions`` maps every type
    in the graph to its full ``ros2msg`` text; ``typedefs`` maps ``pkg/msg/Name`` (and a
    service's ``pkg/srv/Name_Request``/``_Response``) to its rosapi typedefs.
    """

    node: str = ""
    own_node: tuple[str, str] = ("", "/")
    topics: list[tuple[str, list[str]]] = field(default_factory=list)
    services: list[tuple[str, list[str]]] = field(default_factory=list)
    nodes: dict[str, dict[str, Any]] = field(default_factory=dict)
    publishers: dict[str, list[tuple[str, str, dict[str, Any]]]] = field(default_factory=dict)
    subscribers: dict[str, list[tuple[str, str]]] = field(default_factory=dict)
    definitions: dict[str, str] = field(default_factory=dict)
    typedefs: dict[str, list[dict[str, Any]]] = field(default_factory=dict)
    interfaces: list[str] = field(default_factory=list)

    def encode(self) -> bytes:
        """As the ``@graph`` payload."""
        return json.dumps(asdict(self), separators=(",", ":"), sort_keys=True).encode()

    @classmethod
    def decode(cls, data: bytes) -> Snapshot:
        """From a ``@graph`` payload; ``BridgeError`` naming what is wrong."""
        try:
            obj = json.loads(data)
            snap = cls(**obj)
        except (ValueError, TypeError) as exc:
            raise BridgeError(f"a robot's @graph payload is not a Snapshot ({exc})") from None
        snap.own_node = (str(snap.own_node[0]), str(snap.own_node[1]))
        snap.topics = [(str(n), list(t)) for n, t in snap.topics]
        snap.services = [(str(n), list(t)) for n, t in snap.services]
        return snap
