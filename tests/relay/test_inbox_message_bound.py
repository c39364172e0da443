"""A robot's inbox on a relay takes no single message over its byte bound (issue 53): one
over ``--max-robot-message-bytes`` is dropped on Zenoh's thread, never queued, counted as
``message_too_large`` and logged with the robot and its key; a reply over it is counted as
lost for the robot's clients. Messages within it are handled as before."""

from __future__ import annotations

import asyncio
import logging
import threading
from dataclasses import dataclass

import pytest

from bridge_server.zenoh import inbox
from bridge_server.zenoh.inbox import Inbox

pytestmark = pytest.mark.timeout(30)


@dataclass
class Sample:
    """What Zenoh hands a topic callback, as far as the inbox looks at it."""

    payload: bytes
    key_expr: str = "robot1/bomb"


@dataclass
class Reply:
    """What Zenoh hands a reply callback: its sample under ``ok``."""

    ok: Sample


async def _handled(box: Inbox) -> None:
    """Run what Zenoh's thread queued, until nothing waits."""
    while any(box.waiting().values()) or box._scheduled:
        await asyncio.sleep(0)


async def test_a_message_over_the_bound_is_dropped_counted_and_logged(
        caplog: pytest.LogCaptureFixture) -> None:
    """With a bound of 1000 bytes, a 1001-byte message is dropped before it waits (counted,
    logged naming robot1 and its key) and a 1000-byte one is handled; a reply over the bound
    is dropped and the robot's clients are told."""
    box = Inbox(asyncio.get_running_loop(), "robot1", max_message=1000)
    handled: list[int] = []
    told: list[str] = []
    box.told.append(told.append)
    on_sample = box.sample(lambda s: handled.append(len(s.payload)))
    on_reply = box.reliable(lambda r: handled.append(len(r.ok.payload)))
    with caplog.at_level(logging.WARNING, "bridge_server.zenoh.graph"):
        thread = threading.Thread(target=lambda: (on_sample(Sample(bytes(1001))),
                                                  on_sample(Sample(bytes(1000))),
                                                  on_reply(Reply(Sample(bytes(5000), "r/q")))))
        thread.start()
        thread.join()
        assert box.waiting()["message_bytes"] == 1000  # the large one never waited
        await _handled(box)
    assert handled == [1000]
    assert box.faults.counts["message_too_large"] == 2
    assert "robot robot1: a message of 1001 bytes on robot1/bomb, over the limit of 1000 " \
           "bytes a message (--max-robot-message-bytes), dropped" in caplog.text
    assert told and "1 replies or requests from it were dropped" in told[0]


def test_the_bound_is_the_relays_option() -> None:
    """set_message_bytes (the relay's --max-robot-message-bytes) sets the bound of inboxes
    made after it; 0 is refused naming the option."""
    loop = asyncio.new_event_loop()
    try:
        assert Inbox(loop, "r").max_message == inbox.MESSAGE_BYTES
        inbox.set_message_bytes(5)
        assert Inbox(loop, "r").max_message == 5
        with pytest.raises(ValueError, match="--max-robot-message-bytes 0"):
            inbox.set_message_bytes(0)
    finally:
        inbox.set_message_bytes(inbox.MESSAGE_BYTES)
        loop.close()
