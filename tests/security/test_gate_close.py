"""The gate's close holds its closing task until it is done (issue 54: two mutants of
``Gate.close`` survived the gate's unit tests). The event loop keeps only weak references
to tasks, so a close nobody awaits must be held, and let go once done, not kept for ever."""

from __future__ import annotations

import pytest

from rosbridge_core.security import gate as gate_module
from rosbridge_core.security.gate import POLICY_VIOLATION
from tests.security.test_gate_units import _closed, _gate

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
