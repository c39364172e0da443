"""The gate's close holds its closing task until it is done, and a principal known at the
handshake is charged at once (issue 54: mutants of ``Gate.close`` and of the charging
survived the gate's unit tests, the charging checked only through a bridge process). The
event loop keeps only weak references to tasks, so a close nobody awaits must be held, and
let go once done, not kept for ever."""

from __future__ import annotations

import asyncio

import pytest

from rosbridge_core.security import gate as gate_module
from rosbridge_core.security.gate import POLICY_VIOLATION, Gate
from rosbridge_core.session.session import ROSAPI_REQUESTS
from tests.security.test_gate_units import (
    ALICE,
    Holder,
    Session,
    Verifier,
    _closed,
    _gate,
)

pytestmark = pytest.mark.timeout(30)


async def test_a_close_is_held_while_it_runs_and_let_go_once_done() -> None:
    """Right after close, the link's close is a task in the gate's strong set; once it has
    run (the link closed with 1008 and the reason), the set no longer holds it."""
    gate, session, _ = _gate()
    before = set(gate_module._CLOSING)
    gate.close("over the op rate")
    held = gate_module._CLOSING - before
    assert len(held) == 1
    (task,) = held
    assert not task.done()
    assert await _closed(session) == (POLICY_VIOLATION, "over the op rate")
    await task  # its done callbacks (the set's discard first) run before this returns
    assert task not in gate_module._CLOSING


async def test_a_principal_known_at_the_handshake_is_charged_at_once() -> None:
    """A gate made for a link whose token the handshake proved makes the link's memory
    holder count for that principal before any op; without a principal it charges no one."""
    for principal, became in ((ALICE, ["alice"]), (None, [])):
        session = Session(asyncio.get_running_loop())
        session.link.holder = Holder()
        Gate(Verifier(), session, principal, ROSAPI_REQUESTS)  # type: ignore[arg-type]
        assert session.link.holder.became == became
