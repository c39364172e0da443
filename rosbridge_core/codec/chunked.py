"""A large decoded message's JSON text and CBOR bytes made in pieces, for a worker thread.

The standard library's JSON encoder and cbor2's encoder are C functions that hold the
interpreter's lock for the whole of one call: encoding a message of a million small structs
in one call on a worker thread would stop the event loop (every other client) for as long
as the call takes. These encoders walk the decoded message (:mod:`msgs.cdr`'s wire form:
dicts, lists, ``bytes``, typed arrays) in Python and hand the C encoders one small piece at
a time (up to :data:`PIECE` items of a list, each a scalar or a small struct), so that the
loop's thread takes the lock back between pieces (``sys.getswitchinterval``, 5 ms).

Their output is, byte for byte, what one call gives: :func:`json_text` that of
:func:`rosbridge_core.codec.cdr_json.msgs_encoder` (``bytes`` as base64 strings), and
:func:`cbor_bytes` that of ``cbor2.dumps`` (definite lengths, no value sharing), which
``tests/core/test_chunked_codec.py`` checks on real types. Used by
:mod:`bridge_server.zenoh.decode` for messages of
:data:`~rosbridge_core.codec.budget.OFF_LOOP_BYTES` and more; small messages keep the
one-call encoders.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from rosbridge_core.codec.cdr_json import (
    _encode as _json,  # the one-call encoder whose output this matches
)
from rosbridge_core.codec.cdr_json import b64_text

__all__ = ["PIECE", "cbor_bytes", "json_text"]

PIECE = 1024
"""Scalars of a list handed to a C encoder in one call at most."""

def _flat(value: Any, depth: int = 2) -> bool:
    """Whether one C call encodes ``value`` quickly: a scalar or ``bytes``, or a dict or a
    list of at most :data:`PIECE` items of those, ``depth`` levels down (a
    ``geometry_msgs/Pose``, a ``PointField``)."""
    if isinstance(value, dict):
        items: Any = value.values()
    elif isinstance(value, list):
        if len(value) > PIECE:
            return False
        items = value
    else:
        return True
    return depth > 0 and all(_flat(item, depth - 1) for item in items)


def json_text(value: Any) -> str:
    """``value`` as compact JSON (``bytes`` as base64 strings), in pieces; ``ValueError``
    for a NaN or infinity, as the one-call encoder."""
    out: list[str] = []
    _json_into(value, out.append)
    return "".join(out)


def _json_into(value: Any, add: Callable[[str], Any]) -> None:
    if isinstance(value, bytes):  # not scanned for characters to escape: base64 has none
        add(f'"{b64_text(value)}"')
    elif _flat(value):
        add(_json(value))
    elif isinstance(value, dict):
        first = True
        for key, item in value.items():
            add(f'{{{_json(key)}:' if first else f',{_json(key)}:')
            first = False
            _json_into(item, add)
        add("}")
    else:
        add("[")
        for start in range(0, len(value), PIECE):
            piece = value[start:start + PIECE]
            if all(map(_flat, piece)):  # a piece at a time
                add(("," if start else "") + _json(piece)[1:-1])
            else:
                for i, item in enumerate(piece):
                    if start or i:
                        add(",")
                    _json_into(item, add)
        add("]")


def cbor_bytes(value: Any, dumps: Callable[[Any], bytes]) -> bytes:
    """``dumps(value)`` (``cbor2.dumps``), in pieces: containers' heads made here, their
    items a piece at a time."""
    out: list[bytes] = []
    _cbor_into(value, out.append, dumps)
    return b"".join(out)


def _head(major: int, count: int, dumps: Callable[[Any], bytes]) -> bytes:
    """A CBOR head of ``major`` type (0x80 array, 0xa0 map) and ``count``: an unsigned
    integer's encoding with its major type changed."""
    head = dumps(count)
    return bytes((head[0] | major,)) + head[1:]


def _cbor_into(value: Any, add: Callable[[bytes], Any], dumps: Callable[[Any], bytes]) -> None:
    if _flat(value):
        add(dumps(value))
    elif isinstance(value, dict):
        add(_head(0xA0, len(value), dumps))
        for key, item in value.items():
            add(dumps(key))
            _cbor_into(item, add, dumps)
    else:
        add(_head(0x80, len(value), dumps))
        for start in range(0, len(value), PIECE):
            piece = value[start:start + PIECE]
            if all(map(_flat, piece)):  # the piece's items, without its own head
                add(dumps(piece)[len(_head(0x80, len(piece), dumps)):])
            else:
                for item in piece:
                    _cbor_into(item, add, dumps)
