"""What a subscription does with what a sync callback returns: None (the usual) costs nothing
more, an awaitable (a sync-looking callable such as a lambda calling an ``async def``) is run."""

from __future__ import annotations

import asyncio

from roslibpy_lite import MockRos


async def test_an_awaitable_a_sync_callback_returns_is_run() -> None:
    """A lambda that returns a coroutine has the coroutine run, once per message; a callback
    beside it that returns None is called as usual."""
    ros = MockRos()
    seen: list[str] = []
    ran = asyncio.Event()

    async def handle(msg: dict[str, str]) -> None:
        seen.append(msg["data"])
        ran.set()

    sub = ros.subscribe("/t", "std_msgs/msg/String")
    sub.on_message(lambda msg: handle(msg))
    plain: list[str] = []
    sub.on_message(lambda msg: plain.append(msg["data"]))
    await sub
    await ros.advertise("/t", "std_msgs/msg/String").publish({"data": "a"})
    await asyncio.wait_for(ran.wait(), 5)
    assert seen == ["a"] and plain == ["a"]
    assert sub.callback_errors == 0
