"""The rosbridge v2 ops as values: one frozen dataclass per op.

Every op that crosses the wire is parsed in one place (:func:`parse_op`) and
serialized in one place (:func:`to_obj` / :func:`encode`). Parsing checks the
fields the op needs and their kinds, and raises
:class:`~roslibpy_lite.exceptions.RemoteProtocolError` naming the op, the
field and what was expected; fields an op does not know are ignored (stock
clients send a few extras). ``null`` for an optional field means "absent".

The kinds a field may hold live in :mod:`.kinds`; the handshake headers of our extensions
(:data:`ACKS_HEADER` and the others, :func:`parse_received`) in :mod:`.headers`, re-exported
here. The module does no I/O and needs nothing beyond the standard library.
"""

from __future__ import annotations

import base64
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import (
    Annotated,
    Any,
    ClassVar,
    TypeAlias,
    get_args,
)

from .constants import ADVERTISE_QUEUE_SIZE
from .errors import LocalProtocolError, RemoteProtocolError
from .goal_status import GoalStatus
from .headers import (
    ACKS_HEADER,
    AUTH_HEADER,
    RECEIVED_HEADER,
    RELAY_HEADER,
    SESSION_HEADER,
    parse_received,
)
from .kinds import (
    _ANY,
    _ARGS,
    _BOOL,
    _COUNT,
    _ID,
    _INT,
    _MS,
    _NAME,
    _OBJECT,
    _SECONDS,
    _SIZE,
    _STR,
    _VALUES,
    _describe,
    _is_int,
    _Kind,
    _kind_of,
    _Rules,
    _rules_of,
    _same,
)

__all__ = [
    "ACKS_HEADER",
    "AUTH_HEADER",
    "COMPRESSIONS",
    "ENCODINGS",
    "RECEIVED_HEADER",
    "RELAY_HEADER",
    "SESSION_HEADER",
    "ActionFeedback",
    "ActionResultOp",
    "Advertise",
    "AdvertiseAction",
    "AdvertiseService",
    "Auth",
    "CallService",
    "CancelActionGoal",
    "Fragment",
    "Id",
    "Op",
    "Publish",
    "SendActionGoal",
    "ServiceResponse",
    "SessionAck",
    "SetLevel",
    "Status",
    "Subscribe",
    "Unadvertise",
    "UnadvertiseAction",
    "UnadvertiseService",
    "Unsubscribe",
    "encode",
    "op_name",
    "parse_op",
    "parse_received",
    "to_obj",
]

Id: TypeAlias = str | int
"""An interaction id: the peer chooses it, every reply about it echoes it."""

ENCODINGS = ("none", "cbor", "cbor-raw")
"""The encodings a subscribe's ``compression`` may ask our bridge for: JSON text, CBOR, and
CBOR around the message's CDR bytes (the bridge's codecs: ``rosbridge_core.codec.encodings``)."""
COMPRESSIONS = (*ENCODINGS, "png")
"""Every ``compression`` a subscribe may carry (png is legacy: parsed, and answered by our
bridge with plain JSON and a warning)."""


# --- the ops (their fields' kinds: .kinds) ---------------------------------------------

_COMPRESSION = _Kind(
    "one of " + ", ".join(COMPRESSIONS),
    lambda v: v in COMPRESSIONS,
    _same,
)


class _OpFacts:
    """What the bridge and the client derive from an op's class, declared on it once.

    ``NEEDS``: the role capability the op needs (None: it only touches what the sender
    already owns); ``TARGET``: the field naming what it acts on (a topic, service or
    action); ``ACKED``: whether a client that asked for verdicts (:data:`ACKS_HEADER`) is
    told ``ok`` when the op is accepted.
    """

    __slots__ = ()
    OP: ClassVar[str]
    NEEDS: ClassVar[str | None] = None
    TARGET: ClassVar[str | None] = None
    ACKED: ClassVar[bool] = False

    def target(self) -> str | None:
        """The name this op acts on (its :attr:`TARGET` field), if it names one."""
        return getattr(self, self.TARGET) if self.TARGET else None

    def refusal(self, why: str) -> Op | None:
        """The answer a peer waits for when this op is refused (besides the status error),
        if it waits for one."""
        return None


@dataclass(frozen=True, slots=True)
class Advertise(_OpFacts):
    """C→S: announce that this client will publish ``type`` messages on ``topic``."""

    OP: ClassVar[str] = "advertise"
    NEEDS = "publish"
    TARGET = "topic"
    ACKED = True
    topic: Annotated[str, _NAME]
    type: Annotated[str, _NAME]
    id: Annotated[Id | None, _ID] = None
    latch: Annotated[bool, _BOOL] = False
    queue_size: Annotated[int, _COUNT] = ADVERTISE_QUEUE_SIZE


@dataclass(frozen=True, slots=True)
class Unadvertise(_OpFacts):
    """C→S: this client stops publishing on ``topic``."""

    OP: ClassVar[str] = "unadvertise"
    TARGET = "topic"
    topic: Annotated[str, _NAME]
    id: Annotated[Id | None, _ID] = None


@dataclass(frozen=True, slots=True)
class Publish(_OpFacts):
    """Both ways: one message on a topic (the server's copies carry no id)."""

    OP: ClassVar[str] = "publish"
    NEEDS = "publish"
    TARGET = "topic"
    topic: Annotated[str, _NAME]
    msg: Annotated[Mapping[str, Any], _OBJECT]
    id: Annotated[Id | None, _ID] = None
    latch: Annotated[bool | None, _BOOL] = None
    queue_size: Annotated[int | None, _COUNT] = None


@dataclass(frozen=True, slots=True)
class Subscribe(_OpFacts):
    """C→S: deliver the messages of ``topic`` to this client.

    ``throttle_rate`` is the least time between two messages in milliseconds,
    ``queue_length`` how many messages may wait for a slow client (0: the
    server's default bound), ``fragment_size`` splits large messages, and
    ``compression`` is one of ``none``, ``cbor``, ``cbor-raw``.
    """

    OP: ClassVar[str] = "subscribe"
    NEEDS = "subscribe"
    TARGET = "topic"
    ACKED = True
    topic: Annotated[str, _NAME]
    type: Annotated[str | None, _NAME] = None
    id: Annotated[Id | None, _ID] = None
    throttle_rate: Annotated[int, _MS] = 0
    queue_length: Annotated[int, _COUNT] = 0
    fragment_size: Annotated[int | None, _SIZE] = None
    compression: Annotated[str, _COMPRESSION] = "none"


@dataclass(frozen=True, slots=True)
class Unsubscribe(_OpFacts):
    """C→S: end the subscription ``id`` (without id: all of this client's on ``topic``)."""

    OP: ClassVar[str] = "unsubscribe"
    TARGET = "topic"
    topic: Annotated[str, _NAME]
    id: Annotated[Id | None, _ID] = None


@dataclass(frozen=True, slots=True)
class CallService(_OpFacts):
    """Both ways: call ``service`` with ``args``.

    C→S: the client calls a ROS service (``args`` an object, or a list zipped
    onto the request fields in order; ``timeout`` in seconds). S→C: a ROS
    caller reached a service this client serves; answer with
    :class:`ServiceResponse` carrying the same ``id``.
    """

    OP: ClassVar[str] = "call_service"
    NEEDS = "call_service"
    TARGET = "service"
    service: Annotated[str, _NAME]
    args: Annotated[Mapping[str, Any] | list[Any] | None, _ARGS] = None
    type: Annotated[str | None, _NAME] = None
    id: Annotated[Id | None, _ID] = None
    timeout: Annotated[float | None, _SECONDS] = None
    fragment_size: Annotated[int | None, _SIZE] = None
    compression: Annotated[str | None, _COMPRESSION] = None

    def refusal(self, why: str) -> Op | None:
        """A failed :class:`ServiceResponse`: what a stock caller waits for."""
        return ServiceResponse(service=self.service, result=False, values=f"{self.OP}: {why}",
                               id=self.id)


@dataclass(frozen=True, slots=True)
class ServiceResponse(_OpFacts):
    """Both ways: the answer to a :class:`CallService` with the same ``id``.

    On success ``result`` is true and ``values`` the response object; on
    failure ``result`` is false and ``values`` usually a string saying why.
    """

    OP: ClassVar[str] = "service_response"
    TARGET = "service"
    service: Annotated[str, _NAME]
    result: Annotated[bool, _BOOL]
    values: Annotated[Mapping[str, Any] | str | None, _VALUES] = None
    id: Annotated[Id | None, _ID] = None


@dataclass(frozen=True, slots=True)
class AdvertiseService(_OpFacts):
    """C→S: this client serves ``service`` of ``type`` to ROS callers."""

    OP: ClassVar[str] = "advertise_service"
    NEEDS = "serve_service"
    TARGET = "service"
    ACKED = True
    service: Annotated[str, _NAME]
    type: Annotated[str, _NAME]
    id: Annotated[Id | None, _ID] = None


@dataclass(frozen=True, slots=True)
class UnadvertiseService(_OpFacts):
    """C→S: this client stops serving ``service``."""

    OP: ClassVar[str] = "unadvertise_service"
    TARGET = "service"
    service: Annotated[str, _NAME]
    id: Annotated[Id | None, _ID] = None


@dataclass(frozen=True, slots=True)
class SendActionGoal(_OpFacts):
    """Both ways: send a goal to an action server (``args`` an object, or a list zipped onto
    the goal's fields)."""

    OP: ClassVar[str] = "send_action_goal"
    NEEDS = "send_action_goal"
    TARGET = "action"
    action: Annotated[str, _NAME]
    action_type: Annotated[str, _NAME]
    args: Annotated[Mapping[str, Any] | list[Any] | None, _ARGS] = None
    id: Annotated[Id | None, _ID] = None
    feedback: Annotated[bool | None, _BOOL] = None
    fragment_size: Annotated[int | None, _SIZE] = None
    compression: Annotated[str | None, _COMPRESSION] = None

    def refusal(self, why: str) -> Op | None:
        """An aborted :class:`ActionResultOp` for the goal's id: what a stock sender waits
        for (none without an id to name)."""
        if self.id is None:
            return None
        return ActionResultOp(id=self.id, action=self.action, values=f"{self.OP}: {why}",
                              result=False, status=int(GoalStatus.ABORTED))


@dataclass(frozen=True, slots=True)
class CancelActionGoal(_OpFacts):
    """Both ways: cancel the goal ``id`` of ``action``."""

    OP: ClassVar[str] = "cancel_action_goal"
    NEEDS = "send_action_goal"
    TARGET = "action"
    id: Annotated[Id, _ID]
    action: Annotated[str, _NAME]


@dataclass(frozen=True, slots=True)
class ActionFeedback(_OpFacts):
    """Both ways: feedback for the goal ``id``."""

    OP: ClassVar[str] = "action_feedback"
    NEEDS = "serve_action"
    TARGET = "action"
    id: Annotated[Id, _ID]
    action: Annotated[str, _NAME]
    values: Annotated[Mapping[str, Any], _OBJECT]


@dataclass(frozen=True, slots=True)
class ActionResultOp(_OpFacts):
    """Both ways: the result of the goal ``id`` (``status`` is a GoalStatus int)."""

    OP: ClassVar[str] = "action_result"
    NEEDS = "serve_action"
    TARGET = "action"
    id: Annotated[Id, _ID]
    action: Annotated[str, _NAME]
    result: Annotated[bool, _BOOL]
    # roslib's setFailed sends no values
    values: Annotated[Mapping[str, Any] | str | None, _VALUES] = None
    status: Annotated[int | None, _INT] = None


@dataclass(frozen=True, slots=True)
class AdvertiseAction(_OpFacts):
    """C→S: this client serves ``action`` of ``type``."""

    OP: ClassVar[str] = "advertise_action"
    NEEDS = "serve_action"
    TARGET = "action"
    ACKED = True
    action: Annotated[str, _NAME]
    type: Annotated[str, _NAME]
    id: Annotated[Id | None, _ID] = None


@dataclass(frozen=True, slots=True)
class UnadvertiseAction(_OpFacts):
    """C→S: this client stops serving ``action``."""

    OP: ClassVar[str] = "unadvertise_action"
    TARGET = "action"
    action: Annotated[str, _NAME]
    id: Annotated[Id | None, _ID] = None


@dataclass(frozen=True, slots=True)
class Fragment(_OpFacts):
    """Both ways: piece ``num`` (from 0) of ``total`` of a large op's JSON text."""

    OP: ClassVar[str] = "fragment"
    id: Annotated[Id, _ID]
    data: Annotated[str, _STR]
    num: Annotated[int, _COUNT]
    total: Annotated[int, _SIZE]


@dataclass(frozen=True, slots=True)
class Status(_OpFacts):
    """S→C: a report about the server or about the request ``id``."""

    OP: ClassVar[str] = "status"
    level: Annotated[str, _STR]
    msg: Annotated[str, _STR]
    id: Annotated[Id | None, _ID] = None


@dataclass(frozen=True, slots=True)
class SetLevel(_OpFacts):
    """C→S: the least ``status`` level the client wants to hear."""

    OP: ClassVar[str] = "set_level"
    level: Annotated[str, _STR]
    id: Annotated[Id | None, _ID] = None


@dataclass(frozen=True, slots=True)
class SessionAck(_OpFacts):
    """C↔S, in a session negotiated with :data:`SESSION_HEADER` only: the sender has
    received ``count`` frames of this session; the other side may forget those it sent."""

    OP: ClassVar[str] = "session_ack"
    count: Annotated[int, _COUNT]


@dataclass(frozen=True, slots=True)
class Auth(_OpFacts):
    """C→S: rosauth's shape, sent first by roslib's ``authenticate()``; ``mac`` carries a token.

    Never print or log an ``Auth`` op whole: its ``mac`` is a secret.
    """

    OP: ClassVar[str] = "auth"
    mac: Annotated[str, _STR]
    client: Annotated[Any, _ANY] = None
    dest: Annotated[Any, _ANY] = None
    rand: Annotated[Any, _ANY] = None
    t: Annotated[Any, _ANY] = None
    level: Annotated[Any, _ANY] = None
    end: Annotated[Any, _ANY] = None

    def __repr__(self) -> str:
        return "Auth(mac=<hidden>)"


Op: TypeAlias = (
    Advertise
    | Unadvertise
    | Publish
    | Subscribe
    | Unsubscribe
    | CallService
    | ServiceResponse
    | AdvertiseService
    | UnadvertiseService
    | SendActionGoal
    | CancelActionGoal
    | ActionFeedback
    | ActionResultOp
    | AdvertiseAction
    | UnadvertiseAction
    | Fragment
    | Status
    | SetLevel
    | SessionAck
    | Auth
)


# --- parsing -------------------------------------------------------------------

_RULES: dict[str, tuple[type[Any], _Rules]] = {
    cls.OP: (cls, _rules_of(cls)) for cls in get_args(Op)
}

OP_NAMES: frozenset[str] = frozenset(_RULES)
"""Every op name this module parses."""


def parse_op(obj: Any) -> Op:
    """Turn one decoded frame (a JSON object) into its op value.

    Raises:
        RemoteProtocolError: the object is not an op, names no known op, or a
            field is missing or of the wrong kind. The error carries ``op``
            and ``id`` when they could be read, and its message names the
            field and the expected kind.
    """
    if type(obj) is dict and len(obj) == 3 and obj.get("op") == "publish":
        # A message as a server sends it ({op, topic, msg}), the most frequent frame: the
        # same checks as the rules below make, in under half the time (2.0 -> 0.9 us).
        topic, msg = obj.get("topic"), obj.get("msg")
        if type(topic) is str and topic and isinstance(msg, Mapping):
            return Publish(topic, msg)
    if not isinstance(obj, Mapping):
        raise RemoteProtocolError(f"an op must be a JSON object, got {_kind_of(obj)}")
    raw_id = obj.get("id")
    op_id: Id | None = raw_id if (isinstance(raw_id, str) or _is_int(raw_id)) else None
    name = obj.get("op")
    if name is None:
        raise RemoteProtocolError("missing field 'op'", id=op_id)
    if not isinstance(name, str):
        raise RemoteProtocolError(f"field 'op' must be a string, got {_kind_of(name)}", id=op_id)
    entry = _RULES.get(name)
    if entry is None:
        raise RemoteProtocolError(f"unknown op {name!r}", op=name, id=op_id)
    cls, rules = entry
    kwargs: dict[str, Any] = {}
    for field_name, ((expected, check, normalise), required) in rules.items():
        value = obj.get(field_name)
        if value is None:
            if required:
                raise RemoteProtocolError(
                    f"{name}: missing field {field_name!r} ({expected})", op=name, id=op_id
                )
            continue
        if not check(value):
            raise RemoteProtocolError(
                f"{name}: field {field_name!r} must be {expected}, got {_describe(value)}",
                op=name,
                id=op_id,
            )
        kwargs[field_name] = normalise(value)
    op: Op = cls(**kwargs)
    if isinstance(op, Fragment) and op.num >= op.total:
        raise RemoteProtocolError(
            f"fragment: field 'num' ({op.num}) must be less than 'total' ({op.total})",
            op=name,
            id=op_id,
        )
    return op


# --- serializing -----------------------------------------------------------------

def op_name(op: Op) -> str:
    """The wire name of ``op`` (``"publish"`` for a :class:`Publish`)."""
    return op.OP


_FIELD_NAMES: dict[type[Any], tuple[str, ...]] = {
    cls: tuple(rules) for cls, rules in _RULES.values()}
"""Each op class's field names in order (dataclasses.fields() cost 0.4 us an op)."""


def to_obj(op: Op) -> dict[str, Any]:
    """The JSON object for ``op``: ``op`` first, then its fields, absent ones left out."""
    obj: dict[str, Any] = {"op": op.OP}
    names = _FIELD_NAMES.get(type(op))
    for name in names if names is not None else (f.name for f in fields(op)):
        value = getattr(op, name)
        if value is not None:
            obj[name] = value
    return obj


def encode(op: Op) -> str:
    """The JSON text of ``op`` for one websocket text frame.

    Non-finite floats (NaN, ±Inf) go out as ``null``, since JSON has none; bytes
    (a ``uint8[]`` field as a subscription gives it) as base64 text, rosbridge's JSON form;
    a numpy scalar (or 0-d array) as its Python number or bool.

    Raises:
        LocalProtocolError: a value cannot be expressed in JSON.
    """
    obj = to_obj(op)
    try:
        return _JSON.encode(obj)
    except ValueError:
        return _JSON.encode(_finite(obj))
    except TypeError as exc:
        raise LocalProtocolError(f"{op.OP}: cannot encode as JSON: {exc}", op=op.OP) from None


def _base64(value: Any) -> Any:
    if isinstance(value, bytes | bytearray | memoryview):
        return base64.b64encode(value).decode("ascii")
    if getattr(value, "ndim", None) == 0 and type(value).__module__ == "numpy":
        plain = value.item()  # a numpy scalar: its Python value (numpy is not imported)
        return plain if not isinstance(plain, float) or math.isfinite(plain) else None
    raise TypeError(f"Object of type {type(value).__name__} is not JSON serializable")


_JSON = json.JSONEncoder(separators=(",", ":"), allow_nan=False, default=_base64)
"""The encoder of :func:`encode`, made once (json.dumps with options makes one a call: 1 us)."""


def _finite(value: Any) -> Any:
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value
