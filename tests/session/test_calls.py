"""A client's request tasks (:class:`rosbridge_core.session.calls.Calls`): counted while they
run, gone when they end, and all cancelled and awaited when the client leaves."""

from __future__ import annotations

import asyncio

from rosbridge_core.session.calls import Calls


async def test_a_task_is_counted_while_it_runs() -> None:
    calls = Calls(asyncio.get_running_loop())
    release = asyncio.Event()
    ended = asyncio.Event()

    async def call() -> None:
        await release.wait()
        ended.set()

    calls.spawn(call())
    assert len(calls) == 1
    running = list(calls)
    release.set()
    await asyncio.gather(*running)  # its done callbacks, the set's first, have run
    assert ended.is_set() and len(calls) == 0


async def test_cancel_all_cancels_and_awaits_every_task() -> None:
    calls = Calls(asyncio.get_running_loop())
    started = [asyncio.Event() for _ in range(3)]
    cleaned: list[int] = []

    async def call(i: int) -> None:
        started[i].set()
        try:
            await asyncio.Event().wait()
        finally:
            await asyncio.sleep(0)  # clean-up that itself awaits must finish too
            cleaned.append(i)

    for i in range(3):
        calls.spawn(call(i))
    for event in started:
        await event.wait()
    await calls.cancel_all()
    assert sorted(cleaned) == [0, 1, 2]
    assert len(calls) == 0
    await calls.cancel_all()  # nothing left: harmless
