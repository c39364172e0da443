"""The sans-I/O rosbridge core, shared by the client and the bridge.

Frames in, ops out; ops in, text out. Nothing here touches a socket or an
event loop, so it is tested with plain values::

    proto = Conversation()
    op = proto.receive('{"op": "publish", "topic": "/a", "msg": {"data": 1}}')
    assert op == Publish(topic="/a", msg={"data": 1})

What it handles:

- text frames (one JSON object each) and binary frames (one CBOR-encoded op
  each; RFC 8746 typed arrays become lists, byte strings stay ``bytes``);
- ``fragment`` ops, reassembled per id into the op they carry, with bounds on
  how many partial ops and how many bytes may wait;
- splitting an op's text into ``fragment`` ops for a peer that asked for it.

Every bad frame raises :class:`~roslibpy_lite.exceptions.RemoteProtocolError`
naming what was wrong and where; the protocol object stays usable.
"""

from __future__ import annotations

import array
import json
import json.scanner
import sys
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, NoReturn, Protocol

from .constants import MAX_CLIENT_FRAME
from .errors import RemoteProtocolError
from .ops import Fragment, Id, Op, encode, parse_op

__all__ = [
    "PIECE_COST",
    "TYPED_ARRAY_TAGS",
    "Conversation",
    "FragmentBudget",
    "decode_frame",
    "decode_typed_array",
    "split_fragments",
]

# RFC 8746 typed-array tags -> array.array type codes (little-endian variants,
# plus the big-endian ones for completeness). uint8 arrays travel as byte strings.
TYPED_ARRAY_TAGS: dict[int, tuple[str, bool]] = {
    64: ("B", False),   # uint8
    65: ("H", True),    # uint16 big-endian
    66: ("I", True),    # uint32 big-endian
    67: ("Q", True),    # uint64 big-endian
    68: ("B", False),   # uint8 clamped
    69: ("H", False),   # uint16 little-endian
    70: ("I", False),   # uint32 little-endian
    71: ("Q", False),   # uint64 little-endian
    72: ("b", False),   # int8
    73: ("h", True),    # int16 big-endian
    74: ("i", True),    # int32 big-endian
    75: ("q", True),    # int64 big-endian
    77: ("h", False),   # int16 little-endian
    78: ("i", False),   # int32 little-endian
    79: ("q", False),   # int64 little-endian
    81: ("f", True),    # float32 big-endian
    82: ("d", True),    # float64 big-endian
    85: ("f", False),   # float32 little-endian
    86: ("d", False),   # float64 little-endian
}
_LITTLE = sys.byteorder == "little"


def decode_typed_array(tag: int, payload: bytes) -> list[Any]:
    """Decode the byte string of an RFC 8746 typed array into a list of numbers.

    Raises:
        RemoteProtocolError: unknown tag, or a payload whose length is not a
            multiple of the element size.
    """
    try:
        code, big_endian = TYPED_ARRAY_TAGS[tag]
    except KeyError:
        raise RemoteProtocolError(f"CBOR: unknown typed-array tag {tag}") from None
    values = array.array(code)
    if len(payload) % values.itemsize:
        raise RemoteProtocolError(
            f"CBOR: typed array (tag {tag}) of {len(payload)} bytes is not a multiple of "
            f"{values.itemsize}"
        )
    values.frombytes(payload)
    if big_endian == _LITTLE:
        values.byteswap()
    return values.tolist()


def _cbor_loads() -> Callable[[bytes], Any]:
    try:
        import cbor2
    except ImportError:  # pragma: no cover - depends on the install
        raise RemoteProtocolError(
            "a binary (CBOR) frame arrived but cbor2 is not installed; "
            "install roslibpy-lite[cbor]"
        ) from None

    def tag_hook(*args: Any) -> Any:
        # cbor2 5 calls hook(decoder, tag); cbor2 6 calls hook(tag, immutable).
        tag = args[1] if isinstance(args[1], cbor2.CBORTag) else args[0]
        if tag.tag in TYPED_ARRAY_TAGS and isinstance(tag.value, bytes):
            return decode_typed_array(tag.tag, tag.value)
        return tag

    def loads(data: bytes) -> Any:
        return cbor2.loads(data, tag_hook=tag_hook)

    return loads


_cbor_loader: Callable[[bytes], Any] | None = None

_make_scanner: Any = json.scanner.make_scanner  # typeshed types it as a class of its own
_scan_json: Callable[[str, int], tuple[Any, int]] = _make_scanner(json.JSONDecoder())
"""``json.loads``' own scanner (C), without its Python wrapping: (value, end) of the JSON value
at an index (a frame's decoding was a tenth of a small op's time in the bridge)."""


def decode_frame(data: str | bytes) -> Any:
    """Decode one websocket frame: text as JSON, bytes as CBOR.

    Returns the decoded value (normally a dict; :func:`parse_op` checks that).

    Raises:
        RemoteProtocolError: the frame is not valid JSON or CBOR; the message
            says where decoding failed.
    """
    global _cbor_loader
    if isinstance(data, str):
        try:  # the C scanner straight away: a frame is one JSON value, normally an object
            value, end = _scan_json(data, 0)
            if end == len(data):
                return value
        except (StopIteration, ValueError, RecursionError):
            pass  # json.loads below says what is wrong, and where
        try:  # leading or trailing whitespace, extra data, or malformed
            return json.loads(data)
        except json.JSONDecodeError as exc:
            raise RemoteProtocolError(
                f"malformed JSON at line {exc.lineno} column {exc.colno}: {exc.msg}"
            ) from None
        except RecursionError:
            raise RemoteProtocolError("malformed JSON: nested too deeply") from None
    if _cbor_loader is None:
        _cbor_loader = _cbor_loads()
    try:
        return _cbor_loader(bytes(data))
    except RemoteProtocolError:
        raise
    except Exception as exc:  # cbor2 raises several kinds for bad input
        raise RemoteProtocolError(f"malformed CBOR binary frame: {exc}") from None


@dataclass
class _Partial:
    total: int
    pieces: dict[int, str] = field(default_factory=dict)
    size: int = 0


PIECE_COST = 128
"""The least a held fragment piece counts against ``max_fragment_bytes``, however short its
data: a piece's own objects take about that much, so many one-character pieces are held to
the bound as much as a few large ones (a piece of 128 characters or more counts its length)."""


class FragmentBudget(Protocol):
    """Fragment memory shared with other connections (a server's per-principal and
    per-address accounts): each held piece is taken from it, and given back when its op is
    completed or dropped."""

    def take(self, n: int) -> str | None:
        """Take ``n`` bytes; or, if that would pass a limit, take nothing and say which."""

    def give_back(self, n: int) -> None:
        """Return ``n`` bytes taken before."""


class Conversation:
    """One side of a rosbridge conversation, without I/O.

    Args:
        max_partial: how many fragmented ops may be incomplete at once; the
            oldest is dropped past that, and recorded in :attr:`evicted` as
            ``(id, pieces received, total)`` so the caller can tell the sender.
        max_fragment_bytes: how many characters of fragment data may be held, for all the
            incomplete ops together (each piece counts at least :data:`PIECE_COST`); a piece
            that would take them past it is refused, and its op dropped.
        budget: where held pieces are also charged, across connections (``None``: only
            ``max_fragment_bytes`` bounds them); a piece it refuses is refused with its text,
            and its op dropped. Call :meth:`close` when the connection ends.
    """

    def __init__(self, *, max_partial: int = 64, max_fragment_bytes: int = MAX_CLIENT_FRAME,
                 budget: FragmentBudget | None = None):
        self.max_partial = max_partial
        self.max_fragment_bytes = max_fragment_bytes
        self.budget = budget
        self._partial: OrderedDict[Id, _Partial] = OrderedDict()
        self._held = 0  # what the pieces of every incomplete op count, together
        self.evicted: list[tuple[Id, int, int]] = []

    def receive(self, data: str | bytes) -> Op | None:
        """Take one frame; return the op it completes, or ``None``.

        ``None`` means the frame was a fragment of an op not yet complete.

        Raises:
            RemoteProtocolError: the frame, or the op it completes, is invalid.
        """
        return self.receive_decoded(decode_frame(data))

    def receive_decoded(self, obj: Any) -> Op | None:
        """:meth:`receive` for a frame :func:`decode_frame` already decoded."""
        op = parse_op(obj)
        if isinstance(op, Fragment):
            return self.receive_fragment(op)
        return op

    def receive_fragment(self, frag: Fragment) -> Op | None:
        """Add one fragment; return the reassembled op once all pieces are in.

        Raises:
            RemoteProtocolError: naming the fragment id (and the piece): a piece sent twice,
                a ``total`` that changed, more held than ``max_fragment_bytes``, or a
                reassembled op that is invalid. The op's pieces held so far are dropped.
        """
        partial = self._partial.get(frag.id)
        if partial is None:
            partial = self._partial[frag.id] = _Partial(frag.total)
            while len(self._partial) > self.max_partial:
                old_id = next(iter(self._partial))
                old = self._drop(old_id)
                self.evicted.append((old_id, len(old.pieces), old.total))
        elif partial.total != frag.total:
            self._fail(frag, f"total changed from {partial.total} to {frag.total}")
        elif frag.num in partial.pieces:
            self._fail(frag, f"piece {frag.num} of {frag.total} was sent twice")
        cost = max(len(frag.data), PIECE_COST)
        if self._held + cost > self.max_fragment_bytes:
            self._fail(frag, f"piece {frag.num} would take the fragments held for this "
                       f"connection past {self.max_fragment_bytes} bytes")
        if self.budget is not None and (why := self.budget.take(cost)) is not None:
            self._fail(frag, f"piece {frag.num} refused: {why}")
        partial.pieces[frag.num] = frag.data
        partial.size += cost
        self._held += cost
        if len(partial.pieces) < partial.total:
            return None
        self._drop(frag.id)
        text = "".join(partial.pieces[i] for i in range(partial.total))
        try:
            inner = parse_op(decode_frame(text))
        except RemoteProtocolError as exc:
            raise RemoteProtocolError(
                f"fragment {frag.id!r}: reassembled op is invalid: {exc.message}",
                op=exc.op or "fragment",
                id=exc.id if exc.id is not None else frag.id,
            ) from None
        if isinstance(inner, Fragment):
            raise RemoteProtocolError(
                f"fragment {frag.id!r}: a fragment may not carry a fragment",
                op="fragment",
                id=frag.id,
            )
        return inner

    def _drop(self, frag_id: Id) -> _Partial:
        """Forget the pieces of ``frag_id``'s op (held: it is in ``_partial``)."""
        partial = self._partial.pop(frag_id)
        self._held -= partial.size
        if self.budget is not None:
            self.budget.give_back(partial.size)
        return partial

    def close(self) -> None:
        """Drop every incomplete op's pieces (the connection ended), giving their bytes back
        to the budget."""
        for frag_id in list(self._partial):
            self._drop(frag_id)

    def _fail(self, frag: Fragment, why: str) -> NoReturn:
        """Drop ``frag``'s op and raise the error naming it."""
        if frag.id in self._partial:
            self._drop(frag.id)
        raise RemoteProtocolError(f"fragment {frag.id!r}: {why}", op="fragment", id=frag.id)

    @property
    def held_fragment_bytes(self) -> int:
        """What the pieces of the incomplete ops count against ``max_fragment_bytes``."""
        return self._held

    @property
    def pending_fragments(self) -> int:
        """How many fragmented ops are waiting for pieces."""
        return len(self._partial)

    @staticmethod
    def send(op: Op) -> str:
        """The text frame for ``op``."""
        return encode(op)


def split_fragments(text: str, size: int, id: Id) -> list[str]:
    """Split the text of one op into ``fragment`` op texts of at most ``size`` characters of data.

    A text that fits in one piece is returned unchanged, as a single frame.
    """
    if size <= 0:
        raise ValueError("fragment size must be > 0")
    if len(text) <= size:
        return [text]
    total = (len(text) + size - 1) // size
    return [
        encode(Fragment(id=id, data=text[i * size : (i + 1) * size], num=i, total=total))
        for i in range(total)
    ]
