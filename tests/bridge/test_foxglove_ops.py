"""The Foxglove protocol's frames without a socket (bridge_server.foxglove.ops): what each
client frame parses to, and the error text for frames that are wrong."""

from __future__ import annotations

import dataclasses
import json
import struct
import types
import typing
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from bridge_server.foxglove import ops
from bridge_server.foxglove.hub import GraphState, foxglove_schema


def test_subscribe_parses_pairs() -> None:
    """subscribe lists (subscription id, channel id) pairs."""
    op = ops.parse_text('{"op":"subscribe","subscriptions":[{"id":0,"channelId":3},'
                         '{"id":1,"channelId":5}]}')
    assert op == ops.Subscribe(((0, 3), (1, 5)))


@pytest.mark.parametrize(("text", "error"), [
    ("[1]", "must be an object"),
    ("{", "malformed JSON at line 1 column 2"),
    ('{"op":"subscribe","subscriptions":' + "[" * 5000 + "]" * 5000 + "}",
     "malformed JSON: nested too deeply"),
    ('{"op":"nope"}', "unknown op 'nope'"),
    ('{"op":"subscribe"}', "subscribe: 'subscriptions' is missing"),
    ('{"op":"subscribe","subscriptions":[{"id":-1,"channelId":1}]}',
     "subscribe.subscriptions[0].id: expected an integer"),
    ('{"op":"unsubscribe","subscriptionIds":[true]}', "unsubscribe.subscriptionIds[0]"),
    ('{"op":"advertise","channels":[{"id":1,"topic":"/a","encoding":"cdr"}]}',
     "advertise.channels[0]: 'schemaName' is missing"),
    ('{"op":"setParameters","parameters":[{"name":"/n.p","value":1,"type":"int"}]}',
     "setParameters.parameters[0].type"),
    ('{"op":"getParameters","parameterNames":"x"}', "getParameters.parameterNames: expected a list"),
])
def test_bad_text_names_the_field(text: str, error: str) -> None:
    """A malformed JSON op raises OpError naming the op and the field."""
    with pytest.raises(ops.OpError, match=error.replace("[", r"\[").replace("]", r"\]")):
        ops.parse_text(text)


def test_binary_client_frames() -> None:
    """Client message data and service call requests (little-endian ids)."""
    assert ops.parse_binary(b"\x01" + struct.pack("<I", 7) + b"abc") == ops.ClientMessage(
        7, b"abc")
    call = b"\x02" + struct.pack("<III", 4, 9, 3) + b"cdr" + b"\x00\x01\x00\x00"
    assert ops.parse_binary(call) == ops.ServiceCall(4, 9, "cdr", b"\x00\x01\x00\x00")


@pytest.mark.parametrize(("data", "error"), [
    (b"", "empty binary frame"),
    (b"\x09abc", "unknown binary opcode 0x09"),
    (b"\x01\x00", "too short for the channel id"),
    (b"\x02" + struct.pack("<III", 1, 2, 50) + b"cdr", "runs past the frame"),
    (b"\x02" + struct.pack("<III", 1, 2, 1) + b"\xff", "not UTF-8"),
])
def test_bad_binary(data: bytes, error: str) -> None:
    """Bad binary frames raise OpError saying what is wrong."""
    with pytest.raises(ops.OpError, match=error):
        ops.parse_binary(data)


def test_server_frames() -> None:
    """Message data, time and service responses are laid out as the spec's tables say."""
    assert ops.message_data_header(5, 2**40) == b"\x01" + struct.pack("<IQ", 5, 2**40)
    assert ops.time_frame(123) == b"\x02" + struct.pack("<Q", 123)
    assert ops.service_response_frame(1, 2, "cdr", b"xy") == (
        b"\x03" + struct.pack("<III", 1, 2, 3) + b"cdrxy")
    assert ops.json_frame("status", level=2, message="m", id=None) == (
        '{"op":"status","level":2,"message":"m"}')


def test_schema_dependencies_named_as_fields_name_them() -> None:
    """rosbag2's 'MSG: pkg/msg/Name' lines become 'MSG: pkg/Name' for Foxglove's parser."""
    text = "std_msgs/Header header\n" + "=" * 80 + "\nMSG: std_msgs/msg/Header\nstring frame_id\n"
    assert foxglove_schema(text).endswith("MSG: std_msgs/Header\nstring frame_id\n")


def test_graph_update_is_the_difference() -> None:
    """A connection graph update carries what changed and what went, nothing else."""
    old = GraphState({"/a": ["/n1"], "/gone": ["/n1"]}, {}, {"/s": ["/n2"]})
    new = GraphState({"/a": ["/n1"], "/b": ["/n3"]}, {}, {})
    assert new.update_since(old) == {
        "publishedTopics": [{"name": "/b", "publisherIds": ["/n3"]}], "subscribedTopics": [],
        "advertisedServices": [], "removedTopics": ["/gone"], "removedServices": ["/s"]}
    assert new.update_since(new) is None


def test_graph_seen_by_a_role_keeps_only_its_names() -> None:
    """The graph a role sees keeps topics, services and node ids it may see (a topic it sees
    stays when its nodes are hidden); from there an update removes what went out of view."""
    graph = GraphState({"/seen/a": ["/seen_n", "/other"], "/b": ["/seen_n"]},
                       {"/seen/a": ["/other"]}, {"/seen/s": ["/seen_n"], "/s": ["/other"]})
    seen = graph.seen_by(lambda name: name.startswith("/seen"))
    assert seen == GraphState({"/seen/a": ["/seen_n"]}, {"/seen/a": []},
                              {"/seen/s": ["/seen_n"]})
    assert graph.seen_by(lambda name: True) == graph
    assert GraphState().update_since(seen) == {
        "publishedTopics": [], "subscribedTopics": [], "advertisedServices": [],
        "removedTopics": ["/seen/a"], "removedServices": ["/seen/s"]}


def test_json_payloads_are_read_as_rosbridge_reads_frames() -> None:
    """A json-encoded payload nested too deeply or not UTF-8 is a OpError saying so."""
    assert ops.parse_json(b'{"data": "hi"}') == {"data": "hi"}
    with pytest.raises(ops.OpError, match=r"^malformed JSON: nested too deeply$"):
        ops.parse_json(b"[" * 5000 + b"]" * 5000)
    with pytest.raises(ops.OpError, match="not UTF-8"):
        ops.parse_json(b"\"\xff\"")


_JSON = st.recursive(
    st.none() | st.booleans() | st.integers(-2**40, 2**40) | st.floats(allow_nan=False)
    | st.text(max_size=20),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=12), inner,
                                                                 max_size=4),
    max_leaves=12,
)
_KEYS = {"subscribe": ["subscriptions"], "unsubscribe": ["subscriptionIds"],
         "advertise": ["channels"], "unadvertise": ["channelIds"],
         "getParameters": ["parameterNames", "id"], "setParameters": ["parameters", "id"],
         "subscribeParameterUpdates": ["parameterNames"], "fetchAsset": ["uri", "requestId"],
         "nope": []}
_ITEM = st.dictionaries(st.sampled_from(["id", "channelId", "topic", "encoding", "schemaName",
                                         "name", "value", "type"]), _JSON, max_size=8)


def _frame(op: str) -> st.SearchStrategy[str]:
    """JSON frames of ``op`` whose fields hold anything: values, lists of values or items."""
    value = _JSON | st.lists(_JSON | _ITEM, max_size=3)
    fields = st.fixed_dictionaries({k: value for k in _KEYS[op]})
    return fields.map(lambda f: json.dumps({"op": op, **f}))


@given(st.text(max_size=80) | st.sampled_from(sorted(_KEYS)).flatmap(_frame))
def test_any_text_is_an_op_or_a_wire_error(text: str) -> None:
    """Whatever text a client sends parses to an op or raises OpError, nothing else."""
    try:
        op = ops.parse_text(text)
    except ops.OpError as exc:
        assert str(exc)
    else:
        assert _typed(op, type(op)), op


def _typed(value: Any, hint: Any) -> bool:
    """Whether ``value`` is of the type ``hint`` (the ops' annotations), all the way in."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if hint is Any:
        return True
    if isinstance(hint, type) and dataclasses.is_dataclass(hint):
        hints = typing.get_type_hints(hint)
        return isinstance(value, hint) and all(
            _typed(getattr(value, f.name), hints[f.name]) for f in dataclasses.fields(hint))
    if origin in (types.UnionType, typing.Union):
        return any(_typed(value, a) for a in args)
    if origin is tuple:
        if not isinstance(value, tuple):
            return False
        if len(args) == 2 and args[1] is Ellipsis:
            return all(_typed(v, args[0]) for v in value)
        return len(value) == len(args) and all(map(_typed, value, args))
    if hint is int:
        return isinstance(value, int) and not isinstance(value, bool)
    return isinstance(value, hint)


@given(st.binary(max_size=40))
def test_any_bytes_are_an_op_or_a_wire_error(data: bytes) -> None:
    """Whatever binary frame a client sends parses to an op or raises OpError."""
    try:
        op = ops.parse_binary(data)
    except ops.OpError as exc:
        assert str(exc)
    else:
        assert isinstance(op, ops.ClientMessage | ops.ServiceCall)
