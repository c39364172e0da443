"""The tasks one client's requests run in (service calls, goals, parameter requests).

Both protocols' sessions keep one :class:`Calls`: a request's task is spawned into it, the
limit on calls in flight counts it, and when the client leaves every task still running is
cancelled and awaited, so nothing it asked for outlives it.
"""

from __future__ import annotations

import asyncio
from collections.abc import Coroutine
from typing import Any


class Calls(set["asyncio.Task[None]"]):
    """A client's running request tasks: a set (its size is the calls in flight) that spawns
    them on ``loop`` and cancels them all when the client goes."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        super().__init__()
        self.loop = loop

    def spawn(self, coro: Coroutine[Any, Any, None]) -> None:
        """Run ``coro`` as a task of this client's; it leaves the set when it ends."""
        task = self.loop.create_task(coro)
        self.add(task)
        task.add_done_callback(self.discard)

    async def cancel_all(self) -> None:
        """Cancel every task still running and wait until each has ended."""
        for task in list(self):
            task.cancel()
        if self:
            await asyncio.gather(*self, return_exceptions=True)
