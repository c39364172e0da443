"""The ``publish`` op a client is sent, around a message already encoded (no ROS needed).

One message is encoded once and shared by every subscriber; these put the op's envelope
around it: JSON text by concatenation, CBOR with the envelope bytes cached per topic, and
``cbor-raw`` (the CDR bytes with their receive time), whose envelope is made apart from the
bytes it carries (:func:`cbor_raw_parts`), so a camera frame is never copied into it.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any, Protocol

__all__ = ["CborConverter", "cbor_obj_parts", "cbor_raw_parts", "encode_publish_cbor",
           "encode_publish_cbor_obj", "encode_publish_cbor_raw", "encode_publish_json"]

_encode_str: Callable[[str], str] = json.encoder.encode_basestring


def _cbor_dumps(obj: Any) -> bytes:
    """``cbor2.dumps``, imported at the first CBOR message (a client-only install, MockRos's,
    has no cbor2 and asks for no CBOR); rebinds itself to it."""
    global _cbor_dumps
    import cbor2

    _cbor_dumps = cbor2.dumps
    return cbor2.dumps(obj)



class CborConverter(Protocol):
    """What :func:`encode_publish_cbor` needs of a converter."""

    def to_cbor_obj(self, msg: Any) -> Any:
        """The message as a CBOR-ready object."""


def encode_publish_json(topic: str, msg_json: str) -> str:
    """The JSON text of a server-to-client publish op around an already encoded msg."""
    return "".join(('{"op":"publish","topic":', _encode_str(topic), ',"msg":', msg_json, "}"))


_cbor_prefixes: dict[str, bytes] = {}


def _cbor_prefix(topic: str) -> bytes:
    """CBOR of ``{"op": "publish", "topic": topic, "msg": `` (a 3-entry map up to the value)."""
    prefix = _cbor_prefixes.get(topic)
    if prefix is None:
        prefix = b"\xa3" + b"".join(map(_cbor_dumps, ("op", "publish", "topic", topic, "msg")))
        if len(_cbor_prefixes) > 4096:
            _cbor_prefixes.clear()
        _cbor_prefixes[topic] = prefix
    return prefix


def encode_publish_cbor(topic: str, ros_msg: Any, conv: CborConverter) -> bytes:
    """The CBOR bytes of a whole publish op (compression ``"cbor"``).

    Identical to ``cbor2.dumps({"op": "publish", "topic": topic, "msg": obj})``
    with ``obj = conv.to_cbor_obj(ros_msg)``; the envelope bytes are cached per topic.
    """
    return encode_publish_cbor_obj(topic, conv.to_cbor_obj(ros_msg))


def encode_publish_cbor_obj(topic: str, obj: Any) -> bytes:
    """The CBOR bytes of a whole publish op around a message already made a CBOR-ready
    object (the envelope bytes are cached per topic)."""
    return b"".join(cbor_obj_parts(topic, obj))


def cbor_obj_parts(topic: str, obj: Any) -> tuple[bytes, bytes]:
    """:func:`encode_publish_cbor_obj`'s bytes in two parts, the envelope's (cached per
    topic) and the message's, not joined (for a camera frame, the join was one more copy of
    its 921 KB)."""
    return _cbor_prefix(topic), _cbor_dumps(obj)


# the msg map {secs, nsecs, bytes} (a 3-entry map, 0xa3), up to secs's value, and its other keys:
# short text strings, their head 0x60 | length (RFC 8949; no cbor2 needed at import)
_RAW_SECS = b"\xa3\x64secs"
_RAW_NSECS = b"\x65nsecs"
_RAW_BYTES = b"\x65bytes"
_BYTE_STRING = 0x40  # CBOR's major type 2 (a byte string) in a head's first byte


def cbor_raw_parts(topic: str, serialized: bytes, stamp_ns: int) -> tuple[bytes, bytes]:
    """The CBOR of a publish op for compression ``"cbor-raw"`` in two parts: everything up
    to the message's bytes (the head of their byte string included), and those bytes as
    given (``serialized`` itself, not copied). Joined, they are
    :func:`encode_publish_cbor_raw`'s bytes.

    ``cbor2.dumps`` of the whole op copied the payload twice (into its buffer, then into the
    bytes it returns): for a 640x480 rgb8 camera that was 1.8 MB of copies per frame, which
    the outbox avoids by writing the two parts one after the other.
    """
    secs, nsecs = divmod(stamp_ns, 1_000_000_000)
    data = serialized if type(serialized) is bytes else bytes(serialized)
    # a byte string's head is an unsigned integer's (its length, in the same form) with the
    # major type changed
    length = _cbor_dumps(len(data))
    head = b"".join((_cbor_prefix(topic), _RAW_SECS, _cbor_dumps(secs), _RAW_NSECS,
                     _cbor_dumps(nsecs), _RAW_BYTES, bytes((length[0] | _BYTE_STRING,)),
                     length[1:]))
    return head, data


def encode_publish_cbor_raw(topic: str, serialized: bytes, stamp_ns: int) -> bytes:
    """The CBOR bytes of a publish op for compression ``"cbor-raw"``.

    ``serialized`` is the CDR of the message (:func:`serialize`, or what an
    rclpy ``raw=True`` subscription delivers); ``stamp_ns`` the receive time. The same as
    ``cbor2.dumps({"op": "publish", "topic": topic, "msg": {"secs": ..., "nsecs": ...,
    "bytes": serialized}})``, joined from :func:`cbor_raw_parts`.
    """
    return b"".join(cbor_raw_parts(topic, serialized, stamp_ns))
