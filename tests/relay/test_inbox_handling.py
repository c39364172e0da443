"""A robot's data whose handler fails, in the relay's inbox (issue 54: the text and the
cause of ``_drain``'s handling_failed fault went unchecked): counted under its kind with
what failed, logged with its exception, and what came after it still handled."""

from __future__ import annotations

import asyncio
import logging

import pytest

from bridge_server.zenoh.inbox import Inbox
from tests.relay.test_inbox import Item, _from_zenohs_thread

pytestmark = pytest.mark.timeout(30)


async def test_a_failing_handler_is_counted_with_its_cause_and_the_rest_handled(
        caplog: pytest.LogCaptureFixture) -> None:
    """Of three replies, the second's handler raises KeyError: it is counted once as
    handling_failed, saying the exception's type, logged with that exception; the first
    and the third are handled."""
    caplog.set_level(logging.WARNING, "bridge_server")
    box = Inbox(asyncio.get_running_loop(), "robot9")
    cause = KeyError("field")
    handled: list[int] = []
    last = asyncio.Event()

    def handle(item: Item) -> None:
        if item.n == 1:
            raise cause
        handled.append(item.n)
        if item.n == 2:
            last.set()

    reliable = box.reliable(handle)
    _from_zenohs_thread(lambda: [reliable(Item(n)) for n in range(3)])
    await asyncio.wait_for(last.wait(), 10)
    assert handled == [0, 2]
    assert box.faults.counts == {"handling_failed": 1}
    assert box.faults.last == {"handling_failed": "handling what it sent failed (KeyError)"}
    (record,) = caplog.records
    assert record.getMessage().startswith(
        "robot robot9: handling what it sent failed (KeyError) (handling_failed: 1 so far;")
    assert record.exc_info is not None and record.exc_info[1] is cause
