"""The Foxglove WebSocket protocol's ops as values, without I/O (``foxglove.websocket.v1``).

What a client sends is parsed in one place (:func:`parse_text` for JSON ops,
:func:`parse_binary` for the binary ones) into frozen dataclasses; what the server
sends is made in one place (the ``*_frame`` functions). Anything else raises
:class:`OpError`, whose text names the op and the field that is wrong, for the
session to answer with a ``status`` error. No sockets, no event loop, no ROS.

The layout follows the protocol's published specification (foxglove/ws-protocol,
``docs/spec.md``): JSON objects with an ``op`` field; binary frames with a one-byte
opcode and little-endian integers.
"""

from __future__ import annotations

import json
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

from rosbridge_core.protocol.errors import RemoteProtocolError
from rosbridge_core.protocol.frames import decode_frame

__all__ = [
    "SUBPROTOCOL",
    "Channel",
    "ClientAdvertise",
    "ClientChannel",
    "ClientMessage",
    "ClientOp",
    "ClientUnadvertise",
    "FetchAsset",
    "GetParameters",
    "OpError",
    "ServiceCall",
    "SetParameters",
    "Subscribe",
    "SubscribeConnectionGraph",
    "SubscribeParameterUpdates",
    "Unsubscribe",
    "UnsubscribeConnectionGraph",
    "UnsubscribeParameterUpdates",
    "json_frame",
    "message_data_header",
    "parse_binary",
    "parse_json",
    "parse_text",
    "service_response_frame",
    "time_frame",
]

SUBPROTOCOL = "foxglove.websocket.v1"
"""The websocket subprotocol a Foxglove client offers in its handshake."""

STATUS_INFO, STATUS_WARNING, STATUS_ERROR = 0, 1, 2
"""``status`` levels."""

# binary opcodes, server to client
MESSAGE_DATA = 0x01
TIME = 0x02
SERVICE_CALL_RESPONSE = 0x03
# binary opcodes, client to server
CLIENT_MESSAGE_DATA = 0x01
SERVICE_CALL_REQUEST = 0x02

_U32 = struct.Struct("<I")
_MESSAGE_HEAD = struct.Struct("<BIQ")
_TIME = struct.Struct("<BQ")
_CALL_HEAD = struct.Struct("<BIII")
_U32_MAX = 0xFFFFFFFF


class OpError(ValueError):
    """A frame that is not a valid Foxglove client message (the text says what is wrong)."""


@dataclass(frozen=True)
class Channel:
    """A channel the server advertises: one topic, its type and its full definition text."""

    id: int
    topic: str
    schema_name: str
    schema: str
    encoding: str = "cdr"
    schema_encoding: str = "ros2msg"

    def to_json(self) -> dict[str, Any]:
        """The channel as the ``advertise`` op lists it."""
        return {"id": self.id, "topic": self.topic, "encoding": self.encoding,
                "schemaName": self.schema_name, "schema": self.schema,
                "schemaEncoding": self.schema_encoding}


@dataclass(frozen=True)
class Subscribe:
    """``subscribe``: (subscription id, channel id) pairs."""

    subscriptions: tuple[tuple[int, int], ...]


@dataclass(frozen=True)
class Unsubscribe:
    """``unsubscribe``: subscription ids."""

    subscription_ids: tuple[int, ...]


@dataclass(frozen=True)
class ClientChannel:
    """One channel a client advertises to publish on."""

    id: int
    topic: str
    encoding: str
    schema_name: str


@dataclass(frozen=True)
class ClientAdvertise:
    """``advertise`` from the client (client publishing)."""

    channels: tuple[ClientChannel, ...]


@dataclass(frozen=True)
class ClientUnadvertise:
    """``unadvertise`` from the client: its channel ids."""

    channel_ids: tuple[int, ...]


@dataclass(frozen=True)
class GetParameters:
    """``getParameters``: names (empty: all), and the id to answer with."""

    OP: ClassVar[str] = "getParameters"

    names: tuple[str, ...]
    id: str | None


@dataclass(frozen=True)
class SetParameters:
    """``setParameters``: (name, value, type) triples; ``value`` None unsets."""

    parameters: tuple[tuple[str, Any, str | None], ...]
    id: str | None


@dataclass(frozen=True)
class SubscribeParameterUpdates:
    """``subscribeParameterUpdates``: names (empty: all known)."""

    OP: ClassVar[str] = "subscribeParameterUpdates"

    names: tuple[str, ...]


@dataclass(frozen=True)
class UnsubscribeParameterUpdates:
    """``unsubscribeParameterUpdates``: names (empty: all)."""

    names: tuple[str, ...]


@dataclass(frozen=True)
class SubscribeConnectionGraph:
    """``subscribeConnectionGraph``."""

    OP: ClassVar[str] = "subscribeConnectionGraph"


@dataclass(frozen=True)
class UnsubscribeConnectionGraph:
    """``unsubscribeConnectionGraph``."""


@dataclass(frozen=True)
class FetchAsset:
    """``fetchAsset`` (this server has no assets: it is answered with a status error)."""

    uri: str
    request_id: int


@dataclass(frozen=True)
class ClientMessage:
    """Binary client message data: a payload on one of the client's channels."""

    channel_id: int
    payload: bytes


@dataclass(frozen=True)
class ServiceCall:
    """Binary service call request."""

    service_id: int
    call_id: int
    encoding: str
    payload: bytes


ClientOp = (Subscribe | Unsubscribe | ClientAdvertise | ClientUnadvertise | GetParameters
            | SetParameters | SubscribeParameterUpdates | UnsubscribeParameterUpdates
            | SubscribeConnectionGraph | UnsubscribeConnectionGraph | FetchAsset
            | ClientMessage | ServiceCall)


# -- parsing ---------------------------------------------------------------------------------


def _field(obj: Mapping[str, Any], key: str, where: str) -> Any:
    if key not in obj:
        raise OpError(f"{where}: '{key}' is missing")
    return obj[key]


def _uint(value: Any, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= _U32_MAX:
        raise OpError(f"{where}: expected an integer from 0 to {_U32_MAX}, got {value!r:.40}")
    return value


def _text(value: Any, where: str) -> str:
    if not isinstance(value, str):
        raise OpError(f"{where}: expected a string, got {type(value).__name__}")
    return value


def _list(value: Any, where: str) -> Sequence[Any]:
    if not isinstance(value, list):
        raise OpError(f"{where}: expected a list, got {type(value).__name__}")
    return value


def _object(value: Any, where: str) -> Mapping[str, Any]:
    if not isinstance(value, dict):
        raise OpError(f"{where}: expected an object, got {type(value).__name__}")
    return value


def _names(obj: Mapping[str, Any], op: str) -> tuple[str, ...]:
    names = _list(_field(obj, "parameterNames", op), f"{op}.parameterNames")
    return tuple(_text(n, f"{op}.parameterNames[{i}]") for i, n in enumerate(names))


def _optional_id(obj: Mapping[str, Any], op: str) -> str | None:
    value = obj.get("id")
    return None if value is None else _text(value, f"{op}.id")


def _subscribe(obj: Mapping[str, Any]) -> Subscribe:
    subs = _list(_field(obj, "subscriptions", "subscribe"), "subscribe.subscriptions")
    pairs = []
    for i, sub in enumerate(subs):
        where = f"subscribe.subscriptions[{i}]"
        sub = _object(sub, where)
        pairs.append((_uint(_field(sub, "id", where), f"{where}.id"),
                      _uint(_field(sub, "channelId", where), f"{where}.channelId")))
    return Subscribe(tuple(pairs))


def _unsubscribe(obj: Mapping[str, Any]) -> Unsubscribe:
    ids = _list(_field(obj, "subscriptionIds", "unsubscribe"), "unsubscribe.subscriptionIds")
    return Unsubscribe(tuple(_uint(v, f"unsubscribe.subscriptionIds[{i}]")
                             for i, v in enumerate(ids)))


def _advertise(obj: Mapping[str, Any]) -> ClientAdvertise:
    chans = _list(_field(obj, "channels", "advertise"), "advertise.channels")
    out = []
    for i, ch in enumerate(chans):
        where = f"advertise.channels[{i}]"
        ch = _object(ch, where)
        out.append(ClientChannel(
            id=_uint(_field(ch, "id", where), f"{where}.id"),
            topic=_text(_field(ch, "topic", where), f"{where}.topic"),
            encoding=_text(_field(ch, "encoding", where), f"{where}.encoding"),
            schema_name=_text(_field(ch, "schemaName", where), f"{where}.schemaName"),
        ))
    return ClientAdvertise(tuple(out))


def _unadvertise(obj: Mapping[str, Any]) -> ClientUnadvertise:
    ids = _list(_field(obj, "channelIds", "unadvertise"), "unadvertise.channelIds")
    return ClientUnadvertise(tuple(_uint(v, f"unadvertise.channelIds[{i}]")
                                   for i, v in enumerate(ids)))


def _set_parameters(obj: Mapping[str, Any]) -> SetParameters:
    params = _list(_field(obj, "parameters", "setParameters"), "setParameters.parameters")
    out = []
    for i, p in enumerate(params):
        where = f"setParameters.parameters[{i}]"
        p = _object(p, where)
        kind = p.get("type")
        if kind is not None and kind not in ("byte_array", "float64", "float64_array"):
            raise OpError(f"{where}.type: expected byte_array, float64 or float64_array, "
                            f"got {kind!r:.40}")
        out.append((_text(_field(p, "name", where), f"{where}.name"), p.get("value"), kind))
    return SetParameters(tuple(out), _optional_id(obj, "setParameters"))


def _fetch_asset(obj: Mapping[str, Any]) -> FetchAsset:
    return FetchAsset(_text(_field(obj, "uri", "fetchAsset"), "fetchAsset.uri"),
                      _uint(_field(obj, "requestId", "fetchAsset"), "fetchAsset.requestId"))


_PARSERS: dict[str, Any] = {
    "subscribe": _subscribe,
    "unsubscribe": _unsubscribe,
    "advertise": _advertise,
    "unadvertise": _unadvertise,
    "getParameters": lambda o: GetParameters(_names(o, "getParameters"),
                                             _optional_id(o, "getParameters")),
    "setParameters": _set_parameters,
    "subscribeParameterUpdates": lambda o: SubscribeParameterUpdates(
        _names(o, "subscribeParameterUpdates")),
    "unsubscribeParameterUpdates": lambda o: UnsubscribeParameterUpdates(
        _names(o, "unsubscribeParameterUpdates")),
    "subscribeConnectionGraph": lambda o: SubscribeConnectionGraph(),
    "unsubscribeConnectionGraph": lambda o: UnsubscribeConnectionGraph(),
    "fetchAsset": _fetch_asset,
}


def parse_json(data: str | bytes) -> Any:
    """JSON text (a frame, or a payload in the ``json`` encoding) as a value, read as
    rosbridge frames are (:func:`rosbridge_core.protocol.decode_frame`); what is wrong (where
    it is malformed, nested too deeply, not UTF-8) is a :class:`OpError` in rosbridge's
    words."""
    try:
        return decode_frame(data if isinstance(data, str) else data.decode())
    except UnicodeDecodeError as exc:
        raise OpError(f"the JSON text is not UTF-8 ({exc.reason} at byte {exc.start})"
                        ) from None
    except RemoteProtocolError as exc:
        raise OpError(exc.message) from None


def parse_text(text: str) -> ClientOp:
    """One JSON frame from a client as its op; :class:`OpError` says what is wrong."""
    obj = parse_json(text)
    if not isinstance(obj, dict):
        raise OpError(f"a JSON frame must be an object with an 'op', got {type(obj).__name__}")
    op = obj.get("op")
    parser = _PARSERS.get(op) if isinstance(op, str) else None
    if parser is None:
        raise OpError(f"unknown op {op!r:.60}; a client may send "
                        + ", ".join(sorted(_PARSERS)))
    result: ClientOp = parser(obj)
    return result


def parse_binary(data: bytes) -> ClientMessage | ServiceCall:
    """One binary frame from a client; :class:`OpError` says what is wrong."""
    if not data:
        raise OpError("an empty binary frame (expected an opcode byte)")
    opcode = data[0]
    if opcode == CLIENT_MESSAGE_DATA:
        if len(data) < 5:
            raise OpError(f"client message data: {len(data)} bytes, too short for the "
                            "channel id (5 bytes at least)")
        return ClientMessage(_U32.unpack_from(data, 1)[0], bytes(data[5:]))
    if opcode == SERVICE_CALL_REQUEST:
        if len(data) < 13:
            raise OpError(f"service call request: {len(data)} bytes, too short for its "
                            "header (13 bytes at least)")
        _, service_id, call_id, size = _CALL_HEAD.unpack_from(data, 0)
        if 13 + size > len(data):
            raise OpError(f"service call request: the encoding's length ({size}) runs past "
                            f"the frame ({len(data)} bytes)")
        try:
            encoding = bytes(data[13:13 + size]).decode()
        except UnicodeDecodeError:
            raise OpError("service call request: the encoding is not UTF-8 text") from None
        return ServiceCall(service_id, call_id, encoding, bytes(data[13 + size:]))
    raise OpError(f"unknown binary opcode 0x{opcode:02x} (a client may send 0x01 client "
                    "message data and 0x02 service call request)")


# -- making ----------------------------------------------------------------------------------


def json_frame(op: str, **fields: Any) -> str:
    """A JSON op from the server (``None`` fields are left out)."""
    obj = {"op": op}
    obj.update((k, v) for k, v in fields.items() if v is not None)
    return json.dumps(obj, separators=(",", ":"))


def message_data_header(subscription_id: int, stamp_ns: int) -> bytes:
    """The 13 bytes before a message's payload (opcode, subscription id, timestamp)."""
    return _MESSAGE_HEAD.pack(MESSAGE_DATA, subscription_id, stamp_ns)


def time_frame(stamp_ns: int) -> bytes:
    """The binary ``time`` op."""
    return _TIME.pack(TIME, stamp_ns)


def service_response_frame(service_id: int, call_id: int, encoding: str, payload: bytes) -> bytes:
    """The binary service call response."""
    enc = encoding.encode()
    return _CALL_HEAD.pack(SERVICE_CALL_RESPONSE, service_id, call_id, len(enc)) + enc + payload
