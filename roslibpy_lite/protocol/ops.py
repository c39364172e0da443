"""The rosbridge v2 ops as values: one frozen dataclass per op.

Every op that crosses the wire is parsed in one place (:func:`parse_op`) and
serialized in one place (:func:`to_obj` / :func:`encode`). Parsing checks the
fields the op needs and their kinds, and raises
:class:`~roslibpy_lite.exceptions.RemoteProtocolError` naming the op, the
field and what was expected; fields an op does not know are ignored (stock
clients send a few extras). ``null`` for an optional field means "absent".

The module does no I/O and needs nothing beyond the standard library.
"""

from __future__ import annotations

import base64
import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields
from typing import Any, ClassVar, TypeAlias

from .errors import LocalProtocolError, RemoteProtocolError

__all__ = [
    "ACKS_HEADER",
    "AUTH_HEADER",
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

ACKS_HEADER = "X-Rosbridge-Acks"
"""Handshake header of our extension: a client that sends it with ``1`` asks the bridge to
confirm each accepted advertise/subscribe/advertise_service/advertise_action with a
``status`` ``info`` naming the request's id (``ok: <op> <name>``); a bridge that will do so
answers the handshake with the same header. Stock servers ignore it, and are then never waited for.
"""

AUTH_HEADER = "X-Rosbridge-Auth"
"""Handshake response header of our bridge: ``required`` when it requires a token and this
connection brought none (it must then send an ``auth`` op first). A client that has no token
to send can fail at once, saying so, instead of failing at its first op."""

RELAY_HEADER = "X-Rosbridge-Relay"
"""Handshake response header of our relay (``roslibpy-lite-relay``): the robot the path
named (empty when it named none). Its refusals say the robot is not connected, or the role may
not reach it, so a client can say "relay" and, for an offline robot, fail at once (or wait for
it when asked) instead of retrying a bare 404."""

SESSION_HEADER = "X-Rosbridge-Session"
"""Handshake header of our extension for sessions that survive a dropped link. A client
sends ``new`` (or the token of the session it had); a bridge that keeps sessions answers
with the token of this connection's session. Stock servers ignore it."""

RECEIVED_HEADER = "X-Rosbridge-Received"
"""Handshake header that goes with a session token, both ways: how many frames the sender
has received in that session. When the bridge answers it, the session was resumed, and each
side sends again what the other has not received."""


def parse_received(value: str | None, limit: int | None) -> int:
    """The frame count of a :data:`RECEIVED_HEADER` value: ASCII decimal digits only, at most
    ``limit`` (what the other side has sent in the session: no one receives more; ``None``:
    the form alone is checked).

    Raises :class:`~roslibpy_lite.exceptions.RemoteProtocolError` with one line naming the
    header and what is wrong with the value (missing, empty, not ASCII digits, too large).
    """
    if value is None:
        raise RemoteProtocolError(f"{RECEIVED_HEADER} is missing: a resumed session needs "
                                  "the count of frames received")
    shown = ascii(value if len(value) <= 24 else value[:24] + "...")
    if not value:
        raise RemoteProtocolError(f"{RECEIVED_HEADER} is empty: expected the count of frames "
                                  "received (ASCII decimal digits)")
    if not (value.isascii() and value.isdigit()):
        raise RemoteProtocolError(f"{RECEIVED_HEADER} {shown} is not a count of frames "
                                  "(ASCII decimal digits only)")
    if limit is None:
        return int(value)
    digits = value.lstrip("0") or "0"  # int() is not asked to read thousands of digits
    count = int(digits) if len(digits) <= len(str(limit)) else limit + 1
    if count > limit:
        raise RemoteProtocolError(f"{RECEIVED_HEADER} {shown} is more than this session has "
                                  f"sent ({limit} frames)")
    return count

COMPRESSIONS = ("none", "cbor", "cbor-raw", "png")
"""Compression names a subscribe may ask for (png is legacy and refused by our bridge)."""


@dataclass(frozen=True, slots=True)
class Advertise:
    """C→S: announce that this client will publish ``type`` messages on ``topic``."""

    OP: ClassVar[str] = "advertise"
    topic: str
    type: str
    id: Id | None = None
    latch: bool = False
    queue_size: int = 100


@dataclass(frozen=True, slots=True)
class Unadvertise:
    """C→S: this client stops publishing on ``topic``."""

    OP: ClassVar[str] = "unadvertise"
    topic: str
    id: Id | None = None


@dataclass(frozen=True, slots=True)
class Publish:
    """Both ways: one message on a topic (the server's copies carry no id)."""

    OP: ClassVar[str] = "publish"
    topic: str
    msg: Mapping[str, Any]
    id: Id | None = None
    latch: bool | None = None
    queue_size: int | None = None


@dataclass(frozen=True, slots=True)
class Subscribe:
    """C→S: deliver the messages of ``topic`` to this client.

    ``throttle_rate`` is the least time between two messages in milliseconds,
    ``queue_length`` how many messages may wait for a slow client (0: the
    server's default bound), ``fragment_size`` splits large messages, and
    ``compression`` is one of ``none``, ``cbor``, ``cbor-raw``.
    """

    OP: ClassVar[str] = "subscribe"
    topic: str
    type: str | None = None
    id: Id | None = None
    throttle_rate: int = 0
    queue_length: int = 0
    fragment_size: int | None = None
    compression: str = "none"


@dataclass(frozen=True, slots=True)
class Unsubscribe:
    """C→S: end the subscription ``id`` (without id: all of this client's on ``topic``)."""

    OP: ClassVar[str] = "unsubscribe"
    topic: str
    id: Id | None = None


@dataclass(frozen=True, slots=True)
class CallService:
    """Both ways: call ``service`` with ``args``.

    C→S: the client calls a ROS service (``args`` an object, or a list zipped
    onto the request fields in order; ``timeout`` in seconds). S→C: a ROS
    caller reached a service this client serves; answer with
    :class:`ServiceResponse` carrying the same ``id``.
    """

    OP: ClassVar[str] = "call_service"
    service: str
    args: Mapping[str, Any] | list[Any] | None = None
    type: str | None = None
    id: Id | None = None
    timeout: float | None = None
    fragment_size: int | None = None
    compression: str | None = None


@dataclass(frozen=True, slots=True)
class ServiceResponse:
    """Both ways: the answer to a :class:`CallService` with the same ``id``.

    On success ``result`` is true and ``values`` the response object; on
    failure ``result`` is false and ``values`` usually a string saying why.
    """

    OP: ClassVar[str] = "service_response"
    service: str
    result: bool
    values: Mapping[str, Any] | str | None = None
    id: Id | None = None


@dataclass(frozen=True, slots=True)
class AdvertiseService:
    """C→S: this client serves ``service`` of ``type`` to ROS callers."""

    OP: ClassVar[str] = "advertise_service"
    service: str
    type: str
    id: Id | None = None


@dataclass(frozen=True, slots=True)
class UnadvertiseService:
    """C→S: this client stops serving ``service``."""

    OP: ClassVar[str] = "unadvertise_service"
    service: str
    id: Id | None = None


@dataclass(frozen=True, slots=True)
class SendActionGoal:
    """Both ways: send a goal to an action server (``args`` an object, or a list zipped onto
    the goal's fields)."""

    OP: ClassVar[str] = "send_action_goal"
    action: str
    action_type: str
    args: Mapping[str, Any] | list[Any] | None = None
    id: Id | None = None
    feedback: bool | None = None
    fragment_size: int | None = None
    compression: str | None = None


@dataclass(frozen=True, slots=True)
class CancelActionGoal:
    """Both ways: cancel the goal ``id`` of ``action``."""

    OP: ClassVar[str] = "cancel_action_goal"
    id: Id
    action: str


@dataclass(frozen=True, slots=True)
class ActionFeedback:
    """Both ways: feedback for the goal ``id``."""

    OP: ClassVar[str] = "action_feedback"
    id: Id
    action: str
    values: Mapping[str, Any]


@dataclass(frozen=True, slots=True)
class ActionResultOp:
    """Both ways: the result of the goal ``id`` (``status`` is a GoalStatus int)."""

    OP: ClassVar[str] = "action_result"
    id: Id
    action: str
    result: bool
    values: Mapping[str, Any] | str | None = None  # roslib's setFailed sends none
    status: int | None = None


@dataclass(frozen=True, slots=True)
class AdvertiseAction:
    """C→S: this client serves ``action`` of ``type``."""

    OP: ClassVar[str] = "advertise_action"
    action: str
    type: str
    id: Id | None = None


@dataclass(frozen=True, slots=True)
class UnadvertiseAction:
    """C→S: this client stops serving ``action``."""

    OP: ClassVar[str] = "unadvertise_action"
    action: str
    id: Id | None = None


@dataclass(frozen=True, slots=True)
class Fragment:
    """Both ways: piece ``num`` (from 0) of ``total`` of a large op's JSON text."""

    OP: ClassVar[str] = "fragment"
    id: Id
    data: str
    num: int
    total: int


@dataclass(frozen=True, slots=True)
class Status:
    """S→C: a report about the server or about the request ``id``."""

    OP: ClassVar[str] = "status"
    level: str
    msg: str
    id: Id | None = None


@dataclass(frozen=True, slots=True)
class SetLevel:
    """C→S: the least ``status`` level the client wants to hear."""

    OP: ClassVar[str] = "set_level"
    level: str
    id: Id | None = None


@dataclass(frozen=True, slots=True)
class SessionAck:
    """C↔S, in a session negotiated with :data:`SESSION_HEADER` only: the sender has
    received ``count`` frames of this session; the other side may forget those it sent."""

    OP: ClassVar[str] = "session_ack"
    count: int


@dataclass(frozen=True, slots=True)
class Auth:
    """C→S: rosauth's shape, sent first by roslib's ``authenticate()``; ``mac`` carries a token.

    Never print or log an ``Auth`` op whole: its ``mac`` is a secret.
    """

    OP: ClassVar[str] = "auth"
    mac: str
    client: Any = None
    dest: Any = None
    rand: Any = None
    t: Any = None
    level: Any = None
    end: Any = None

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

# A kind is (what it is called in errors, a check, a normaliser).
_Kind: TypeAlias = tuple[str, Callable[[Any], bool], Callable[[Any], Any]]


def _same(value: Any) -> Any:
    return value


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value: Any) -> bool:
    return (isinstance(value, int | float)) and not isinstance(value, bool)


def _as_ms(value: Any) -> int:
    return int(value)


_STR: _Kind = ("a string", lambda v: isinstance(v, str), _same)
_NAME: _Kind = ("a non-empty string", lambda v: isinstance(v, str) and v != "", _same)
_ID: _Kind = ("a string or an integer", lambda v: isinstance(v, str) or _is_int(v), _same)
_BOOL: _Kind = ("true or false", lambda v: isinstance(v, bool), _same)
_INT: _Kind = ("an integer", _is_int, _same)
_COUNT: _Kind = ("an integer >= 0", lambda v: _is_int(v) and v >= 0, _same)
_SIZE: _Kind = ("an integer > 0", lambda v: _is_int(v) and v > 0, _same)
_MS: _Kind = ("a number of milliseconds >= 0", lambda v: _is_number(v) and v >= 0, _as_ms)
_SECONDS: _Kind = (
    "a number of seconds > 0",
    lambda v: _is_number(v) and v > 0 and math.isfinite(v),
    float,
)
_OBJECT: _Kind = ("an object", lambda v: isinstance(v, Mapping), _same)
_ARGS: _Kind = ("an object or a list", lambda v: isinstance(v, Mapping | list), _same)
_VALUES: _Kind = ("an object or a string", lambda v: isinstance(v, Mapping | str), _same)
_COMPRESSION: _Kind = (
    "one of " + ", ".join(COMPRESSIONS),
    lambda v: v in COMPRESSIONS,
    _same,
)

# op name -> (class, {field: (kind, required)})
_Rules: TypeAlias = dict[str, tuple[_Kind, bool]]
_RULES: dict[str, tuple[type[Any], _Rules]] = {}


def _rule(cls: type[Any], **rules: tuple[_Kind, bool]) -> None:
    _RULES[cls.OP] = (cls, rules)


REQ, OPT = True, False
_rule(Advertise, topic=(_NAME, REQ), type=(_NAME, REQ), id=(_ID, OPT), latch=(_BOOL, OPT),
      queue_size=(_COUNT, OPT))
_rule(Unadvertise, topic=(_NAME, REQ), id=(_ID, OPT))
_rule(Publish, topic=(_NAME, REQ), msg=(_OBJECT, REQ), id=(_ID, OPT), latch=(_BOOL, OPT),
      queue_size=(_COUNT, OPT))
_rule(Subscribe, topic=(_NAME, REQ), type=(_NAME, OPT), id=(_ID, OPT), throttle_rate=(_MS, OPT),
      queue_length=(_COUNT, OPT), fragment_size=(_SIZE, OPT), compression=(_COMPRESSION, OPT))
_rule(Unsubscribe, topic=(_NAME, REQ), id=(_ID, OPT))
_rule(CallService, service=(_NAME, REQ), args=(_ARGS, OPT), type=(_NAME, OPT), id=(_ID, OPT),
      timeout=(_SECONDS, OPT), fragment_size=(_SIZE, OPT), compression=(_COMPRESSION, OPT))
_rule(ServiceResponse, service=(_NAME, REQ), result=(_BOOL, REQ), values=(_VALUES, OPT),
      id=(_ID, OPT))
_rule(AdvertiseService, service=(_NAME, REQ), type=(_NAME, REQ), id=(_ID, OPT))
_rule(UnadvertiseService, service=(_NAME, REQ), id=(_ID, OPT))
_rule(SendActionGoal, action=(_NAME, REQ), action_type=(_NAME, REQ), args=(_ARGS, OPT),
      id=(_ID, OPT), feedback=(_BOOL, OPT), fragment_size=(_SIZE, OPT),
      compression=(_COMPRESSION, OPT))
_rule(CancelActionGoal, id=(_ID, REQ), action=(_NAME, REQ))
_rule(ActionFeedback, id=(_ID, REQ), action=(_NAME, REQ), values=(_OBJECT, REQ))
_rule(ActionResultOp, id=(_ID, REQ), action=(_NAME, REQ), values=(_VALUES, OPT),
      result=(_BOOL, REQ), status=(_INT, OPT))
_rule(AdvertiseAction, action=(_NAME, REQ), type=(_NAME, REQ), id=(_ID, OPT))
_rule(UnadvertiseAction, action=(_NAME, REQ), id=(_ID, OPT))
_rule(Fragment, id=(_ID, REQ), data=(_STR, REQ), num=(_COUNT, REQ), total=(_SIZE, REQ))
_rule(Status, level=(_STR, REQ), msg=(_STR, REQ), id=(_ID, OPT))
_rule(SetLevel, level=(_STR, REQ), id=(_ID, OPT))
_rule(SessionAck, count=(_COUNT, REQ))
_ANY: _Kind = ("anything", lambda v: True, _same)
_rule(Auth, mac=(_STR, REQ), client=(_ANY, OPT), dest=(_ANY, OPT), rand=(_ANY, OPT),
      t=(_ANY, OPT), level=(_ANY, OPT), end=(_ANY, OPT))

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


def _kind_of(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, int | float):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, Mapping):
        return "an object"
    return type(value).__name__


def _describe(value: Any) -> str:
    if isinstance(value, str | int | float | bool):
        text = json.dumps(value)
        return f"{_kind_of(value)} {text if len(text) <= 40 else text[:37] + '...'}"
    return _kind_of(value)


# --- serializing -----------------------------------------------------------------

def op_name(op: Op) -> str:
    """The wire name of ``op`` (``"publish"`` for a :class:`Publish`)."""
    return op.OP


def to_obj(op: Op) -> dict[str, Any]:
    """The JSON object for ``op``: ``op`` first, then its fields, absent ones left out."""
    obj: dict[str, Any] = {"op": op.OP}
    for f in fields(op):
        value = getattr(op, f.name)
        if value is not None:
            obj[f.name] = value
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
        return json.dumps(obj, separators=(",", ":"), allow_nan=False, default=_base64)
    except ValueError:
        return json.dumps(_finite(obj), separators=(",", ":"), allow_nan=False,
                          default=_base64)
    except TypeError as exc:
        raise LocalProtocolError(f"{op.OP}: cannot encode as JSON: {exc}", op=op.OP) from None


def _base64(value: Any) -> Any:
    if isinstance(value, bytes | bytearray | memoryview):
        return base64.b64encode(value).decode("ascii")
    if getattr(value, "ndim", None) == 0 and type(value).__module__ == "numpy":
        plain = value.item()  # a numpy scalar: its Python value (numpy is not imported)
        return plain if not isinstance(plain, float) or math.isfinite(plain) else None
    raise TypeError(f"Object of type {type(value).__name__} is not JSON serializable")


def _finite(value: Any) -> Any:
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value
