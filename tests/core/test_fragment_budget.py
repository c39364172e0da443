"""The protocol core's fragment reassembly charges a shared budget (a server's per-principal
and per-address accounts): a piece the budget refuses is refused with its text and its op
dropped, and every byte taken is given back when an op completes, is dropped or the
connection ends."""

from __future__ import annotations

import pytest

from rosbridge_core.protocol.errors import RemoteProtocolError
from rosbridge_core.protocol.frames import PIECE_COST, Conversation
from rosbridge_core.protocol.ops import Fragment


class Budget:
    """A budget of ``limit`` bytes shared by every protocol given it."""

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self.taken = 0

    def take(self, n: int) -> str | None:
        """Take ``n`` bytes unless that passes the limit."""
        if self.taken + n > self.limit:
            return f"over the shared {self.limit}"
        self.taken += n
        return None

    def give_back(self, n: int) -> None:
        """Return ``n`` bytes."""
        self.taken -= n


def piece(id: str, num: int, total: int, data: str) -> Fragment:
    """One fragment op."""
    return Fragment(id=id, data=data, num=num, total=total)


def test_two_connections_share_one_budget_and_a_refused_piece_drops_its_op() -> None:
    """Two protocols (two connections) charging one budget: the piece that would pass it is
    refused naming the fragment, the piece and the budget's reason, and its op's pieces are
    given back while the other connection's stay charged."""
    budget = Budget(3 * PIECE_COST)
    first, second = Conversation(budget=budget), Conversation(budget=budget)
    assert first.receive_fragment(piece("a", 0, 3, "x")) is None
    assert second.receive_fragment(piece("b", 0, 3, "y")) is None
    assert second.receive_fragment(piece("b", 1, 3, "y")) is None
    assert budget.taken == 3 * PIECE_COST
    with pytest.raises(RemoteProtocolError) as refused:
        first.receive_fragment(piece("a", 1, 3, "x"))
    assert refused.value.message == (f"fragment 'a': piece 1 refused: over the shared "
                                     f"{3 * PIECE_COST}")
    assert refused.value.id == "a"
    assert first.pending_fragments == 0 and budget.taken == 2 * PIECE_COST


def test_completed_and_closed_ops_give_their_bytes_back() -> None:
    """An op whose pieces are all in gives back what they took; close() gives back what the
    incomplete ops of a connection that ended took."""
    budget = Budget(10 * PIECE_COST)
    proto = Conversation(budget=budget)
    text = '{"op": "set_level", "level": "info"}'
    assert proto.receive_fragment(piece("whole", 0, 2, text[:10])) is None
    assert proto.receive_fragment(piece("whole", 1, 2, text[10:])) is not None
    assert budget.taken == 0
    proto.receive_fragment(piece("left", 0, 5, "z" * 300))
    proto.receive_fragment(piece("also", 0, 5, "z"))
    assert budget.taken == 300 + PIECE_COST
    proto.close()
    assert budget.taken == 0 and proto.pending_fragments == 0
