"""Each wire encoding of a received message, declared once (no ROS needed).

A subscription's ``compression`` names how the messages of its topic reach the client
(:data:`rosbridge_core.protocol.ops.ENCODINGS`); this module holds, for each name, how a
received message becomes the whole ``publish`` op in it (:data:`ENCODINGS`). A message is
encoded at most once per encoding, and shared by every client that asked for that
encoding (:class:`EncodedMessage`); the ROS sides (rclpy's :class:`Incoming
<bridge_server.rclpy_graph.node.Incoming>`, the relay's :class:`ZenohMessage
<bridge_server.zenoh.graph.ZenohMessage>`) only say how their message reads as JSON text
and as a CBOR object.

A new encoding is one entry here, the name in ``ops.ENCODINGS`` and its codec.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from rosbridge_core.codec.publish import cbor_obj_parts, cbor_raw_parts, encode_publish_json
from rosbridge_core.protocol.ops import ENCODINGS as NAMES

__all__ = ["ENCODINGS", "Encoded", "EncodedMessage", "Encoding"]

Encoded = str | bytes | tuple[bytes, bytes]
"""A whole ``publish`` op as an encoding makes it: text (JSON), bytes, or bytes in two parts
to be sent one after the other without joining them: a head and the payload (``cbor-raw``:
the bytes the ROS side received, :func:`~rosbridge_core.codec.publish.cbor_raw_parts`;
``cbor``: the message's CBOR, :func:`~rosbridge_core.codec.publish.cbor_obj_parts`)."""


class EncodedMessage:
    """One message received on a topic, encoded for clients lazily and once per encoding.

    ``data`` is the message as the ROS side received it (CDR with its 4-byte header),
    ``stamp_ns`` when (nanoseconds since the epoch). Subclasses say how it reads as JSON
    text (:meth:`message_json`) and as a CBOR object (:meth:`cbor_obj`).
    """

    __slots__ = ("_encoded", "data", "framed", "stamp_ns", "topic")

    def __init__(self, topic: str, data: bytes, stamp_ns: int) -> None:
        self.topic = topic
        self.data = data
        self.stamp_ns = stamp_ns
        self._encoded: dict[str, Encoded] = {}
        self.framed: dict[tuple[str, str | None], Any] | None = None
        """Its websocket frames by (encoding, topic spelling), made by the first client's
        outbox and shared by the others (:func:`rosbridge_core.session.outbox.shared_frame`)."""

    def encoded(self, encoding: str, name: str | None = None) -> Encoded:
        """The whole ``publish`` op in ``encoding`` (a key of :data:`ENCODINGS`): text for
        JSON, bytes for the binary ones (a pair of them for ``cbor-raw``: see
        :data:`Encoded`). ``name`` is the topic as the client spelt it (``chatter`` for
        ``/chatter``); the message itself is still encoded once."""
        if name is None or name == self.topic:
            done = self._encoded.get(encoding)
            if done is None:
                done = self._encoded[encoding] = ENCODINGS[encoding].make(self, self.topic)
            return done
        return ENCODINGS[encoding].make(self, name)

    def json_text(self, name: str | None = None) -> str:
        """The whole ``publish`` op as JSON text (``encoded("none", name)``)."""
        text = self.encoded("none", name)
        assert isinstance(text, str)
        return text

    def message_json(self) -> str:
        """The message alone as JSON text."""
        raise NotImplementedError

    def cbor_obj(self) -> Any:
        """The message alone as a CBOR-ready object."""
        raise NotImplementedError


@dataclass(frozen=True)
class Encoding:
    """How a received message becomes a ``publish`` op on the wire."""

    name: str
    """What a subscribe's ``compression`` says to ask for it."""
    binary: bool
    """Whether its frames are binary (CBOR) rather than text; text may be fragmented."""
    make: Callable[[EncodedMessage, str], Encoded]
    """The whole op for a message, under the topic name given."""


ENCODINGS: dict[str, Encoding] = {e.name: e for e in (
    Encoding("none", False, lambda m, topic: encode_publish_json(topic, m.message_json())),
    Encoding("cbor", True, lambda m, topic: cbor_obj_parts(topic, m.cbor_obj())),
    Encoding("cbor-raw", True, lambda m, topic: cbor_raw_parts(topic, m.data, m.stamp_ns)),
)}
"""Every encoding the bridge serves, by name."""

if tuple(ENCODINGS) != NAMES:  # pragma: no cover - a name added on one side only
    raise ImportError(f"the bridge's encodings {tuple(ENCODINGS)} are not the protocol's "
                      f"{NAMES}")
