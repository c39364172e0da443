"""The ``publish`` op a client is sent, around a message already encoded (no ROS needed).

One message is encoded once and shared by every subscriber; these put the op's envelope
around it: JSON text by concatenation, CBOR with the envelope bytes cached per topic, and
``cbor-raw`` (the CDR bytes with their receive time).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any, Protocol

import cbor2

__all__ = ["CborConverter", "encode_publish_cbor", "encode_publish_cbor_obj",
           "encode_publish_cbor_raw", "encode_publish_json"]

_encode_str: Callable[[str], str] = json.encoder.encode_basestring
_cbor_dumps: Callable[[Any], bytes] = cbor2.dumps


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
        prefix = b"\xa3" + b"".join(map(cbor2.dumps, ("op", "publish", "topic", topic, "msg")))
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
    return _cbor_prefix(topic) + _cbor_dumps(obj)


def encode_publish_cbor_raw(topic: str, serialized: bytes, stamp_ns: int) -> bytes:
    """The CBOR bytes of a publish op for compression ``"cbor-raw"``.

    ``serialized`` is the CDR of the message (:func:`serialize`, or what an
    rclpy ``raw=True`` subscription delivers); ``stamp_ns`` the receive time.
    """
    secs, nsecs = divmod(stamp_ns, 1_000_000_000)
    return cbor2.dumps(
        {
            "op": "publish",
            "topic": topic,
            "msg": {"secs": secs, "nsecs": nsecs, "bytes": bytes(serialized)},
        }
    )
