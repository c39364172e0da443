"""The protocol core's fragment limits, at their edges (issue 54: mutation testing of
rosbridge_core/protocol/frames.py left these unchecked): what an evicted op records, what a
bad reassembled op's error names, where split_fragments cuts, and what a shared budget is
charged and given back."""

from __future__ import annotations

import pytest

from rosbridge_core.protocol.errors import RemoteProtocolError
from rosbridge_core.protocol.frames import PIECE_COST, Conversation, decode_frame, split_fragments
from rosbridge_core.protocol.ops import Fragment, Publish, encode, parse_op


def _piece(text: str) -> Fragment:
    """The fragment op a frame's text holds."""
    op = parse_op(decode_frame(text))
    assert isinstance(op, Fragment), op
    return op


class Budget:
    """A shared fragment budget that refuses past ``room`` bytes, recording each call."""

    def __init__(self, room: int) -> None:
        self.room = room
        self.taken = 0
        self.calls: list[tuple[str, int]] = []

    def take(self, n: int) -> str | None:
        self.calls.append(("take", n))
        if self.taken + n > self.room:
            return f"principal alice holds {self.taken} bytes of fragments already"
        self.taken += n
        return None

    def give_back(self, n: int) -> None:
        self.calls.append(("give_back", n))
        self.taken -= n


def test_the_default_holds_64_incomplete_ops_and_records_the_evicted() -> None:
    """64 incomplete ops wait by default; the 65th evicts the oldest, recorded as (id, pieces
    received, total) for the sender to be told."""
    proto = Conversation()
    for i in range(64):
        proto.receive_fragment(Fragment(f"f{i}", "x", 0, 3))
    proto.receive_fragment(Fragment("f0", "y", 1, 3))  # f0 now has 2 of its 3 pieces
    assert proto.evicted == []
    proto.receive_fragment(Fragment("f64", "x", 0, 2))
    assert proto.evicted == [("f0", 2, 3)] and proto.pending_fragments == 64


def test_a_bad_reassembled_op_is_named_by_its_own_op_and_id_when_it_has_them() -> None:
    """Invalid JSON reassembled: the error is the fragment's (op "fragment", the fragment's
    id); a valid op missing a field: the error names that op and its own id."""
    proto = Conversation()
    proto.receive_fragment(Fragment("f1", "{not", 0, 2))
    with pytest.raises(RemoteProtocolError) as garbage:
        proto.receive_fragment(Fragment("f1", " json", 1, 2))
    assert (garbage.value.op, garbage.value.id) == ("fragment", "f1")
    inner = '{"op": "subscribe", "id": "sub-7"}'
    proto.receive_fragment(Fragment("f2", inner[:10], 0, 2))
    with pytest.raises(RemoteProtocolError, match=r"^fragment 'f2': reassembled op is invalid: "
                                                  ) as partial:
        proto.receive_fragment(Fragment("f2", inner[10:], 1, 2))
    assert (partial.value.op, partial.value.id) == ("subscribe", "sub-7")
    inner = '{"op": "subscribe"}'
    with pytest.raises(RemoteProtocolError) as no_id:
        proto.receive_fragment(Fragment("f3", inner, 0, 1))
    assert (no_id.value.op, no_id.value.id) == ("subscribe", "f3")


def test_a_fragment_may_not_carry_a_fragment() -> None:
    """A reassembled fragment op is refused, naming the outer fragment's id."""
    nested = encode(Fragment("inner", "{}", 0, 2))
    proto = Conversation()
    with pytest.raises(RemoteProtocolError) as info:
        proto.receive_fragment(Fragment("outer", nested, 0, 1))
    assert info.value.message == "fragment 'outer': a fragment may not carry a fragment"
    assert (info.value.op, info.value.id) == ("fragment", "outer")
    assert proto.pending_fragments == 0


@pytest.mark.parametrize("length", [9, 10, 11, 12])
def test_split_fragments_cuts_into_pieces_of_the_size(length: int) -> None:
    """A text is cut in pieces of ``size`` characters, the last one shorter, each naming
    how many there are; they reassemble into the text (lengths around a multiple of 5)."""
    text = "x" * length
    frames = [_piece(f) for f in split_fragments(text, 5, "s")]
    assert [len(f.data) for f in frames] == [5] * (length // 5) + ([length % 5] if length % 5
                                                                   else [])
    assert {f.total for f in frames} == {len(frames)}
    assert "".join(f.data for f in frames) == text


def test_split_fragments_edges() -> None:
    """A text of exactly ``size`` stays one frame; a size of 1 cuts every character; a size
    of 0 or less is refused."""
    assert split_fragments("abcde", 5, "s") == ["abcde"]
    assert len(split_fragments("abc", 1, "s")) == 3
    for size in (0, -1):
        with pytest.raises(ValueError, match=r"^fragment size must be > 0$"):
            split_fragments("abc", size, "s")


def test_each_piece_is_taken_from_the_shared_budget_and_given_back() -> None:
    """Each piece held is taken from the budget (its cost: at least PIECE_COST); the op's
    pieces are given back together once it completes."""
    op = Publish("/a", {"data": "x" * 300})
    pieces = split_fragments(encode(op), 200, "b")
    budget = Budget(10_000)
    proto = Conversation(budget=budget)
    assert [proto.receive(p) for p in pieces][-1] == op
    costs = [max(len(_piece(p).data), PIECE_COST) for p in pieces]
    assert budget.calls == [*(("take", c) for c in costs), ("give_back", sum(costs))]
    assert budget.taken == 0


def test_a_piece_the_budget_refuses_is_refused_with_its_reason() -> None:
    """A piece the shared budget refuses fails naming the piece and the budget's reason,
    and the op's pieces held so far are given back."""
    budget = Budget(PIECE_COST)
    proto = Conversation(budget=budget)
    proto.receive_fragment(Fragment("f", "x", 0, 3))
    with pytest.raises(RemoteProtocolError) as info:
        proto.receive_fragment(Fragment("f", "y", 1, 3))
    assert info.value.message == (f"fragment 'f': piece 1 refused: principal alice holds "
                                  f"{PIECE_COST} bytes of fragments already")
    assert (info.value.op, info.value.id) == ("fragment", "f")
    assert budget.taken == 0 and proto.pending_fragments == 0


def test_closing_gives_every_held_piece_back() -> None:
    """close() drops the incomplete ops and gives their bytes back to the budget."""
    budget = Budget(10_000)
    proto = Conversation(budget=budget)
    proto.receive_fragment(Fragment("a", "x" * 500, 0, 2))
    proto.receive_fragment(Fragment("b", "x", 0, 2))
    assert budget.taken == 500 + PIECE_COST
    proto.close()
    assert budget.taken == 0 and proto.pending_fragments == 0
