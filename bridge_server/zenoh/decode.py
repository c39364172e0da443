"""A robot's large messages decoded and encoded off the event loop, in order per topic.

Every robot of a relay shares one event loop; a message is decoded from its CDR bytes and
encoded for its viewers once (:class:`~bridge_server.zenoh.graph.ZenohMessage`). On the loop,
a message of a million small structs stopped every other robot's viewers for seconds
(issue 53: 4.99 s). Now a message of
:data:`~rosbridge_core.codec.budget.OFF_LOOP_BYTES` (64 KiB) or more is decoded and
encoded, in the encodings its topic's viewers asked for, on a worker thread
(:func:`prepare`), in pieces the loop's thread can come between
(:mod:`rosbridge_core.codec.chunked`); only then do its viewers get it, and the topic's
later messages wait behind it (:class:`TopicLane`: at most :data:`WAITING` and
:data:`WAITING_BYTES`, the oldest dropped and counted), so a large message delays its own
topic and no other. A viewer that
asked for the bytes as they came (``cbor-raw``, Foxglove) costs no decoding at all.

What a message may cost decoded is bounded by :class:`msgs.cdr.Budget` (the relay's
``--decode-budget-per-byte``, ``--decode-budget-floor``): one over it is dropped for the
viewers that need it decoded, counted and logged as the robot's fault with the topic, the
field and the budget; its raw viewers still get it.
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from typing import Any, Protocol

import cbor2

from msgs import cdr
from rosbridge_core.codec.budget import OFF_LOOP_BYTES, explain
from rosbridge_core.codec.chunked import cbor_bytes, json_text
from rosbridge_core.codec.lane import OrderedLane, off_loop
from rosbridge_core.codec.publish import _cbor_prefix


class ZenohMessage(Protocol):
    """What this module needs of a robot's message (the relay's ``graph.ZenohMessage``;
    named here as a protocol so that this module does not import the graph back)."""

    topic: str
    data: bytes

    @property
    def conv(self) -> Any: ...
    def take_json(self, text: str) -> None: ...
    def encoded(self, encoding: str, name: str | None = ...) -> object: ...
    def take_encoded(self, encoding: str, value: Any) -> None: ...
    def refuse(self, why: str) -> None: ...


class ZenohFeed(Protocol):
    """What a :class:`TopicLane` needs of its topic's feed (the relay's ``graph.ZenohFeed``)."""

    topic: str

    @property
    def graph(self) -> Any: ...
    def decoded_encodings(self) -> Collection[str]: ...
    def fan_out(self, msg: Any) -> None: ...

__all__ = ["DECODED", "WAITING", "WAITING_BYTES", "TopicLane", "prepare", "wanted"]


WAITING = 64
"""Messages of one topic waiting behind one being prepared, at most (the oldest go)."""

WAITING_BYTES = 64 * 1024 * 1024
"""And their bytes at most (as a robot's inbox: :data:`~.inbox.SAMPLE_BYTES`)."""

DECODED = ("none", "cbor")
"""The encodings made from the decoded message (``cbor-raw`` is the bytes as they came)."""

def wanted(listener: Callable[[Any], None]) -> str | None:
    """The encoding a topic's listener encodes messages in: a rosbridge subscription's
    ``compression``; ``None`` for one that frames the bytes as they came (Foxglove) or
    that this module does not know (it encodes on the loop, as before)."""
    owner = getattr(listener, "__self__", None)
    if owner is None or getattr(owner, "encode", None) is not None:
        return None
    found = getattr(owner, "compression", None)
    return found if isinstance(found, str) else None


def prepare(msg: ZenohMessage, encodings: Collection[str]) -> str | None:
    """(On a worker thread.) Decode ``msg`` once and make its ``encodings`` (of
    :data:`DECODED`), kept on it for every viewer; what went wrong, or ``None``."""
    try:
        if "none" in encodings:
            conv = msg.conv
            values = conv.decode(msg.data)
            try:
                text = json_text(values)
            except ValueError:  # a NaN or infinity: null, as rosbridge sends them
                text = conv.to_json(conv.cls.from_json(values))
            del values
            msg.take_json(text)
            msg.encoded("none")
        if "cbor" in encodings:
            obj = msg.conv.decode_cbor(msg.data)
            msg.take_encoded("cbor", (_cbor_prefix(msg.topic), cbor_bytes(obj, cbor2.dumps)))
    except cdr.CdrError as exc:
        return explain(exc)
    except Exception as exc:  # the robot's bytes, whatever they hold, must not stop the relay
        return f"{type(exc).__name__}: {exc}"
    return None


class TopicLane:
    """One topic's messages on their way to its viewers, in order: a large one prepared on a
    worker thread first, the ones after it waiting for it (see the module text; the order
    and the bounds are an :class:`~rosbridge_core.codec.lane.OrderedLane`'s)."""

    def __init__(self, feed: ZenohFeed) -> None:
        self.feed = feed
        self.lane: OrderedLane[ZenohMessage] = OrderedLane(
            self._handle, max_waiting=WAITING, max_bytes=WAITING_BYTES,
            size=lambda msg: len(msg.data), drop_oldest=True)

    def take(self, msg: ZenohMessage) -> bool:
        """Whether ``msg`` goes this way (a large one, or one behind it); if not, the caller
        hands it to the viewers now."""
        if not self.lane.busy and (len(msg.data) < OFF_LOOP_BYTES
                                   or not self.feed.decoded_encodings()):
            return False
        dropped = self.lane.push(msg)
        if dropped:
            self.feed.graph.faults.add(
                "messages_dropped", f"messages of {self.feed.topic} dropped, the oldest first, "
                f"while a large one was decoded (at most {WAITING} and {WAITING_BYTES} bytes "
                "wait)", dropped)
        return True

    async def _handle(self, msg: ZenohMessage) -> None:
        needs = self.feed.decoded_encodings()
        failed = None
        if needs and len(msg.data) >= OFF_LOOP_BYTES:
            failed = await off_loop(lambda m: prepare(m, needs), msg)
        if failed is not None:  # its raw viewers still get it
            msg.refuse(failed)
        self.feed.fan_out(msg)

    def close(self) -> None:
        """The topic is no longer read: what waits is dropped."""
        self.lane.close()
