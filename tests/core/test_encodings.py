"""Each encoding a client may ask for is one entry of the bridge's registry, shared by both
ROS sides: what it makes of a message, once per message."""

from __future__ import annotations

import json
from typing import Any

import cbor2

from rosbridge_core.codec.encodings import ENCODINGS, EncodedMessage
from rosbridge_core.protocol import ops


class _Played(EncodedMessage):
    """A received message whose JSON text and CBOR object are given, counting each making."""

    __slots__ = ("made",)

    def __init__(self) -> None:
        super().__init__("/chatter", b"\x00\x01\x00\x00\x03\x00\x00\x00hi\x00", 1_500_000_000)
        self.made: list[str] = []

    def message_json(self) -> str:
        self.made.append("json")
        return '{"data":"hi"}'

    def cbor_obj(self) -> Any:
        self.made.append("cbor")
        return {"data": "hi"}


def test_every_encoding_a_client_may_ask_for_is_served_once_per_message() -> None:
    """Each name in ops.ENCODINGS makes the whole publish op (text for JSON, bytes for the
    binary ones, in two parts: cbor-raw's a head and the received bytes themselves), under the
    topic as the client spelt it, and the message's own is made once and shared."""
    assert tuple(ENCODINGS) == ops.ENCODINGS
    for name, encoding in ENCODINGS.items():
        message = _Played()
        first = message.encoded(name)
        assert message.encoded(name) is first, name  # kept: every viewer shares it
        assert isinstance(first, str) is not encoding.binary, name
        spelt = message.encoded(name, "chatter")
        if isinstance(spelt, tuple):  # a head and a payload, not joined
            assert name != "cbor-raw" or spelt[1] is message.data, name
            spelt = b"".join(spelt)
        op = cbor2.loads(spelt) if isinstance(spelt, bytes) else json.loads(spelt)
        assert op["op"] == "publish" and op["topic"] == "chatter", (name, op)
        if name == "cbor-raw":
            assert op["msg"] == {"secs": 1, "nsecs": 500_000_000, "bytes": message.data}
        else:
            assert op["msg"] == {"data": "hi"}, name
        assert len(message.made) <= 2, (name, message.made)
