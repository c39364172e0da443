"""The Foxglove protocol's frames without a socket (bridge_server.foxglove.wire): what each
client frame parses to, and the error text for frames that are wrong."""

from __future__ import annotations

import struct

import pytest

from bridge_server.foxglove import wire
from bridge_server.foxglove.hub import GraphState, foxglove_schema


def test_subscribe_parses_pairs() -> None:
    """subscribe lists (subscription id, channel id) pairs."""
    op = wire.parse_text('{"op":"subscribe","subscriptions":[{"id":0,"channelId":3},'
                         '{"id":1,"channelId":5}]}')
    assert op == wire.Subscribe(((0, 3), (1, 5)))


@pytest.mark.parametrize(("text", "error"), [
    ("[1]", "must be an object"),
    ("{", "not JSON"),
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
    """A malformed JSON op raises WireError naming the op and the field."""
    with pytest.raises(wire.WireError, match=error.replace("[", r"\[").replace("]", r"\]")):
        wire.parse_text(text)


def test_binary_client_frames() -> None:
    """Client message data and service call requests (little-endian ids)."""
    assert wire.parse_binary(b"\x01" + struct.pack("<I", 7) + b"abc") == wire.ClientMessage(
        7, b"abc")
    call = b"\x02" + struct.pack("<III", 4, 9, 3) + b"cdr" + b"\x00\x01\x00\x00"
    assert wire.parse_binary(call) == wire.ServiceCall(4, 9, "cdr", b"\x00\x01\x00\x00")


@pytest.mark.parametrize(("data", "error"), [
    (b"", "empty binary frame"),
    (b"\x09abc", "unknown binary opcode 0x09"),
    (b"\x01\x00", "too short for the channel id"),
    (b"\x02" + struct.pack("<III", 1, 2, 50) + b"cdr", "runs past the frame"),
    (b"\x02" + struct.pack("<III", 1, 2, 1) + b"\xff", "not UTF-8"),
])
def test_bad_binary(data: bytes, error: str) -> None:
    """Bad binary frames raise WireError saying what is wrong."""
    with pytest.raises(wire.WireError, match=error):
        wire.parse_binary(data)


def test_server_frames() -> None:
    """Message data, time and service responses are laid out as the spec's tables say."""
    assert wire.message_data_header(5, 2**40) == b"\x01" + struct.pack("<IQ", 5, 2**40)
    assert wire.time_frame(123) == b"\x02" + struct.pack("<Q", 123)
    assert wire.service_response_frame(1, 2, "cdr", b"xy") == (
        b"\x03" + struct.pack("<III", 1, 2, 3) + b"cdrxy")
    assert wire.json_frame("status", level=2, message="m", id=None) == (
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
