"""What the keys of the relay's wire contract (:mod:`.keys`) carry: each payload as a
dataclass with its JSON codec and the checks that name what is wrong (:class:`Meta`, a
message put's attachment; :class:`CallRequest`, :class:`GoalRequest`, :class:`GoalEvent`,
:class:`Execute`, :class:`ParamRequest`, the queries' payloads and replies;
:class:`Snapshot`, the robot's ``@graph`` document). :mod:`.keys` names them again, so
``keys.Meta`` and the rest stay where the contract's readers look."""

from __future__ import annotations

import base64
import json
import math
from dataclasses import asdict, dataclass, field
from typing import Any, ClassVar, cast

from bridge_server.zenoh.chunks import HEX, check_relay
from rosbridge_core.interfaces import BridgeError

__all__ = ["CallRequest", "Execute", "GoalEvent", "GoalRequest", "Meta", "ParamRequest",
           "Snapshot"]


def _seconds(value: Any, what: str) -> float:
    """``value`` as seconds to wait: a finite number, not negative; ``ValueError`` naming
    ``what`` if not (a NaN would make a deadline nothing reaches)."""
    seconds = float(value)
    if not math.isfinite(seconds) or seconds < 0:
        raise ValueError(f"{what} {value!r} is not a number of seconds")
    return seconds


def _decode_json(data: bytes, what: str) -> dict[str, Any]:
    """A JSON object from a payload; ``BridgeError`` naming ``what`` it should have been."""
    try:
        obj = json.loads(data)
    except ValueError as exc:
        raise BridgeError(f"{what} is not JSON ({exc})") from None
    if not isinstance(obj, dict):
        raise BridgeError(f"{what} is not a JSON object")
    return obj


_COMPACT = json.JSONEncoder(separators=(",", ":"))
"""The one encoder of every payload (``json.dumps`` with ``separators`` makes one per call)."""


class _Payload:
    """A dataclass carried as compact JSON (a query's payload, a put's attachment)."""

    def encode(self) -> bytes:
        """As the payload's bytes."""
        return _COMPACT.encode(asdict(cast(Any, self))).encode()


@dataclass
class Meta(_Payload):
    """The attachment of a message's put: its type, whether the topic is latched (transient
    local), the robot's receive time, its place in the topic's stream (``epoch``: this
    stream, new each time the robot subscribes the topic anew; ``seq``: counted in it from 1)
    so a relay that also asked for the latched message takes each message once, and
    ``zid``: the Zenoh id of the robot's session that put it, which is the id in its
    ``@alive`` token; a relay drops what a session other than the name's holder put (a
    robot refused the name, :class:`Claims`)."""

    type: str
    latched: bool = False
    stamp_ns: int = 0
    epoch: str = ""
    seq: int = 0
    zid: str = ""

    def encode(self) -> bytes:
        """As the attachment's bytes: made for every message a robot puts, so from its fields
        directly (``asdict`` copied each field deeply: 8 us a message, now 2); ``zid`` only
        when set (the bytes are the last release's without it)."""
        fields = {"type": self.type, "latched": self.latched, "stamp_ns": self.stamp_ns,
                  "epoch": self.epoch, "seq": self.seq}
        if self.zid:
            fields["zid"] = self.zid
        return _COMPACT.encode(fields).encode()

    @classmethod
    def decode(cls, data: bytes | None) -> Meta:
        """From an attachment's bytes; ``BridgeError`` naming what is wrong."""
        try:
            obj = json.loads(data or b"")
            return cls(type=str(obj["type"]), latched=bool(obj.get("latched")),
                       stamp_ns=int(obj.get("stamp_ns", 0)), epoch=str(obj.get("epoch", "")),
                       seq=int(obj.get("seq", 0)), zid=str(obj.get("zid", "")))
        except (ValueError, KeyError, TypeError) as exc:
            raise BridgeError(f"a message's attachment is not a Meta object ({exc})") from None


@dataclass
class CallRequest(_Payload):
    """A service call's query payload: what ``Graph.call_service`` takes, as JSON."""

    type: str | None
    args: Any
    timeout: float
    discovery_wait: float

    @classmethod
    def decode(cls, data: bytes) -> CallRequest:
        """From a query's payload; ``BridgeError`` naming what is wrong."""
        try:
            obj = json.loads(data)
            return cls(type=obj["type"], args=obj["args"],
                       timeout=_seconds(obj["timeout"], "timeout"),
                       discovery_wait=_seconds(obj["discovery_wait"], "discovery_wait"))
        except (ValueError, KeyError, TypeError) as exc:
            raise BridgeError(f"a service call's payload is not a CallRequest ({exc})") from None


@dataclass
class GoalRequest(_Payload):
    """A goal's query payload: the action's type, the goal as rosbridge JSON, whether the
    relay wants feedback, which relay sent it and its id there (its ``@running`` token), and
    how long the robot waits for an action server to be ready."""

    type: str
    goal: Any
    feedback: bool
    relay: str
    id: str
    timeout: float

    @classmethod
    def decode(cls, data: bytes) -> GoalRequest:
        """From a query's payload; ``BridgeError`` naming what is wrong."""
        obj = _decode_json(data, "a goal's payload")
        try:
            return cls(type=str(obj["type"]), goal=obj["goal"], feedback=bool(obj["feedback"]),
                       relay=check_relay(str(obj["relay"])), id=check_relay(str(obj["id"])),
                       timeout=_seconds(obj["timeout"], "timeout"))
        except (KeyError, TypeError, ValueError) as exc:
            raise BridgeError(f"a goal's payload is not a GoalRequest ({exc!r})") from None


@dataclass
class GoalEvent:
    """One reply to a goal's query: ``accepted`` (``uuid``: the goal's id in ROS, hex),
    ``rejected``, ``feedback`` (``values``), ``cancel`` (``code``: the CancelGoal return
    code), ``result`` (``status`` and ``values``, None if the goal never ran), or ``failed``
    (``text``: why the goal could not be sent)."""

    event: str
    values: Any = None
    status: int = 0
    code: int = 0
    uuid: str = ""
    text: str = ""

    EVENTS: ClassVar[tuple[str, ...]] = ("accepted", "rejected", "feedback", "cancel",
                                         "result", "failed")

    def encode(self) -> bytes:
        """As a reply's payload (only the fields that are set)."""
        obj = {k: v for k, v in asdict(self).items() if v or k == "event"}
        return _COMPACT.encode(obj).encode()

    @classmethod
    def decode(cls, data: bytes) -> GoalEvent:
        """From a reply's payload; ``BridgeError`` naming what is wrong."""
        obj = _decode_json(data, "a goal's reply")
        if obj.get("event") not in cls.EVENTS:
            raise BridgeError(f"a goal's reply has no known event ({obj.get('event')!r})")
        try:
            event = cls(event=obj["event"], values=obj.get("values"),
                        status=int(obj.get("status", 0)), code=int(obj.get("code", 0)),
                        uuid=str(obj.get("uuid", "")), text=str(obj.get("text", "")))
        except (TypeError, ValueError) as exc:
            raise BridgeError(f"a goal's reply is not a GoalEvent ({exc})") from None
        if not HEX.match(event.uuid):
            raise BridgeError(f"a goal's reply has a uuid that is not hex ({event.uuid!r:.40})")
        return event


@dataclass
class Execute(_Payload):
    """What the robot asks of a relay whose client serves an action: carry out the ROS goal
    ``id`` (``goal``: rosbridge JSON), or (``cancel``) a ROS caller's cancel of it."""

    id: str
    goal: Any = None
    cancel: bool = False

    @classmethod
    def decode(cls, data: bytes) -> Execute:
        """From a query's payload; ``BridgeError`` naming what is wrong."""
        obj = _decode_json(data, "a served goal's payload")
        try:
            return cls(id=check_relay(str(obj["id"])), goal=obj.get("goal"),
                       cancel=bool(obj.get("cancel", False)))
        except KeyError as exc:
            raise BridgeError(f"a served goal's payload is not an Execute ({exc!r})") from None


def _to_text(value: Any) -> tuple[Any, bool]:
    """A parameter value as JSON takes it: a byte array as its base64 text and ``True``
    (JSON has no bytes), anything else as it is and ``False``."""
    if isinstance(value, bytes | bytearray):
        return base64.b64encode(value).decode(), True
    return value, False


def _from_text(value: Any, what: str) -> bytes:
    """The byte array a binary-flagged value's base64 text holds; ``BridgeError`` naming
    ``what`` if it is not base64 text."""
    try:
        if not isinstance(value, str):
            raise ValueError(f"a {type(value).__name__}")
        return base64.b64decode(value, validate=True)
    except ValueError as exc:
        raise BridgeError(f"{what}'s binary value is not base64 text ({exc})") from None


@dataclass
class ParamRequest(_Payload):
    """A parameter query's payload: ``op`` ``names`` (with ``timeout``), ``get`` (``name``)
    or ``set`` (``name``, ``value``; None unsets it). A byte array ``value`` (JSON has no
    bytes) goes as its base64 text with ``"binary": true`` beside it. The reply is the Graph
    method's answer as JSON (:meth:`answer`), a ``get`` of a byte array as
    ``[true, base64 text, true]``; an error reply is
    ``{"kind": "timeout"|"lookup"|"value"|"error", "text"}``."""

    op: str
    name: str = ""
    value: Any = None
    timeout: float = 0.0

    OPS: ClassVar[tuple[str, ...]] = ("names", "get", "set")

    def encode(self) -> bytes:
        """As the payload's bytes (a byte array value as base64, flagged ``binary``)."""
        obj = asdict(self)
        obj["value"], binary = _to_text(self.value)
        if binary:
            obj["binary"] = True
        return _COMPACT.encode(obj).encode()

    @classmethod
    def decode(cls, data: bytes) -> ParamRequest:
        """From a query's payload; ``BridgeError`` naming what is wrong."""
        obj = _decode_json(data, "a parameter request")
        if obj.get("op") not in cls.OPS:
            raise BridgeError(f"a parameter request's op {obj.get('op')!r} is not one of "
                              f"{', '.join(cls.OPS)}")
        value = obj.get("value")
        if obj.get("binary"):
            value = _from_text(value, "a parameter request")
        try:
            return cls(op=obj["op"], name=str(obj.get("name", "")), value=value,
                       timeout=_seconds(obj.get("timeout", 0.0), "timeout"))
        except (TypeError, ValueError) as exc:
            raise BridgeError(f"a parameter request is not a ParamRequest ({exc})") from None

    def answer(self, result: Any) -> bytes:
        """The reply's payload: the Graph method's ``result`` for this request as JSON; a
        ``get``'s byte array value as base64 text with ``true`` after it."""
        if self.op == "get":
            is_set, value = result
            value, binary = _to_text(value)
            result = [is_set, value, True] if binary else [is_set, value]
        return _COMPACT.encode(result).encode()

    def read_answer(self, data: bytes) -> Any:
        """The Graph method's result from a reply's payload (:meth:`answer`'s);
        ``BridgeError`` naming what is wrong."""
        try:
            result = json.loads(data)
        except ValueError as exc:
            raise BridgeError(f"the answer to a parameter {self.op} is not JSON ({exc})") \
                from None
        if self.op != "get":
            return result
        if not isinstance(result, list) or len(result) not in (2, 3):
            raise BridgeError(f"the answer to a parameter get is not [is set, value]: "
                              f"{str(result)[:80]}")
        is_set, value, *binary = result
        if binary and binary[0] is True:
            value = _from_text(value, "the answer to a parameter get")
        return bool(is_set), value


_Shape = Any
"""What :func:`_check_shape` checks: a type (``str``: a string), ``[shape]`` (a list of
those), a tuple of shapes (a list of exactly those), ``{str: shape}`` (an object whose
values are those) or a dict of field names to shapes (an object with those fields)."""

_NAMES_TYPES = [(str, [str])]
_SNAPSHOT: dict[str, _Shape] = {
    "node": str, "own_node": (str, str), "topics": _NAMES_TYPES, "services": _NAMES_TYPES,
    "nodes": {str: {"name": str, "namespace": str, "subscribes": [str], "publishes": [str],
                    "serves": _NAMES_TYPES}},
    "publishers": {str: [(str, str, {str: object})]}, "subscribers": {str: [(str, str)]},
    "definitions": {str: str}, "typedefs": {str: [{str: object}]}, "interfaces": [str],
    "served": {str: str},
}


def _names_and_types(value: Any) -> bool:
    """Whether ``value`` has the shape :data:`_NAMES_TYPES` (a fast path: a robot's topics
    may be 90,000, checked on the relay's worker thread while its loop waits for Python's
    lock; the general walk took 0.55 s of it per document, this ~0.1 s)."""
    return type(value) is list and all(
        type(item) is list and len(item) == 2 and type(item[0]) is str
        and type(item[1]) is list and all(type(t) is str for t in item[1]) for item in value)


def _check_shape(value: Any, shape: _Shape, where: str) -> None:
    """``ValueError`` naming the place in ``value`` that does not have ``shape``."""
    if shape is _NAMES_TYPES and _names_and_types(value):
        return  # else the walk below names the place that is wrong
    if isinstance(shape, type):
        ok = isinstance(value, shape)
    elif isinstance(shape, tuple):
        ok = isinstance(value, list) and len(value) == len(shape)
        for i, (item, each) in enumerate(zip(value, shape, strict=True) if ok else ()):
            _check_shape(item, each, f"{where}[{i}]")
    elif isinstance(shape, list):
        ok = isinstance(value, list)
        for i, item in enumerate(value if ok else ()):
            _check_shape(item, shape[0], f"{where}[{i}]")
    elif str in shape:
        ok = isinstance(value, dict)
        for k, item in (value.items() if ok else ()):
            _check_shape(item, shape[str], f"{where}.{k}")
    else:
        ok = isinstance(value, dict) and set(shape) <= set(value)
        for k in shape if ok else ():
            _check_shape(value[k], shape[k], f"{where}.{k}")
    if not ok:
        raise ValueError(f"{where} is not {_shape_name(shape)}")


def _shape_name(shape: _Shape) -> str:
    if isinstance(shape, type):
        return "a string" if shape is str else "a value"
    if isinstance(shape, tuple):
        return f"a list of {len(shape)} items"
    if isinstance(shape, list):
        return "a list"
    return "an object" if str in shape else f"an object with {', '.join(shape)}"


@dataclass
class Snapshot:
    """The robot's ROS graph as the relays see it (``@graph``).

    ``nodes`` maps ``/ns/name`` to ``{"name", "namespace", "subscribes", "publishes",
    "serves": [[service, [types]], ...]}``; ``publishers`` maps a topic to ``[[node,
    namespace, qos], ...]`` (the QoS in rosbag2's words); ``definitions`` maps every type
    in the graph to its full ``ros2msg`` text (an action server's ``pkg/action/Name``
    too); ``typedefs`` maps ``pkg/msg/Name`` (and a service's ``pkg/srv/Name_Request``/
    ``_Response``, an action's ``pkg/action/Name_Goal``/``_Result``/``_Feedback``) to its
    rosapi typedefs; ``served`` maps a service the robot serves for a relay's client to
    that relay's id.
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
    served: dict[str, str] = field(default_factory=dict)

    def encode(self) -> bytes:
        """As the ``@graph`` payload."""
        return json.dumps(asdict(self), separators=(",", ":"), sort_keys=True).encode()

    @classmethod
    def decode(cls, data: bytes) -> Snapshot:
        """From a ``@graph`` payload; ``BridgeError`` naming the field whose shape is wrong
        (fields it does not know are left out)."""
        obj = _decode_json(data, "a robot's @graph payload")
        known = {name: value for name, value in obj.items() if name in _SNAPSHOT}
        try:  # a newer robot's fields are left out; every known one must have its shape
            for name, value in known.items():
                _check_shape(value, _SNAPSHOT[name], name)
        except ValueError as exc:
            raise BridgeError(f"a robot's @graph payload is not a Snapshot ({exc})") from None
        snap = cls(**known)
        snap.own_node = (snap.own_node[0], snap.own_node[1])
        snap.topics = [(n, t) for n, t in snap.topics]
        snap.services = [(n, t) for n, t in snap.services]
        return snap
