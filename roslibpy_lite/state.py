"""The connection state and who waits on it: :class:`StateHub`, :class:`StateWatcher`.

The client (:mod:`roslibpy_lite.ros`) owns one :class:`StateHub`; its
``on_state_change``, ``state_changes`` and ``wait_connected`` are the hub's.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections import deque
from collections.abc import Callable
from typing import Any, Self

from ._api_types import ConnectionState, StateCallback
from .exceptions import ConnectionClosed, RosTimeoutError

__all__ = ["StateHub", "StateWatcher", "add_callback"]

log = logging.getLogger("roslibpy_lite.client")


def add_callback(callbacks: list[Any], callback: Any) -> Callable[[], None]:
    """Append ``callback`` to ``callbacks``; returns a function that removes it again."""
    callbacks.append(callback)

    def remove() -> None:
        with contextlib.suppress(ValueError):
            callbacks.remove(callback)

    return remove


# --- connection state ------------------------------------------------------------------------

class StateWatcher:
    """An async iterator of connection states, from its creation on.

    Ends after yielding ``CLOSED``. Use ``async with`` (or :meth:`close`) to
    stop watching early.
    """

    def __init__(self, hub: StateHub) -> None:
        self._hub = hub
        self._queue: deque[ConnectionState] = deque()
        self._waiter: asyncio.Future[None] | None = None
        self._done = hub.state is ConnectionState.CLOSED

    def _push(self, state: ConnectionState) -> None:
        self._queue.append(state)
        if self._waiter is not None and not self._waiter.done():
            self._waiter.set_result(None)

    def __aiter__(self) -> Self:
        return self

    async def __anext__(self) -> ConnectionState:
        while not self._queue:
            if self._done:
                raise StopAsyncIteration
            self._waiter = asyncio.get_running_loop().create_future()
            try:
                await self._waiter
            finally:
                self._waiter = None
        state = self._queue.popleft()
        if state is ConnectionState.CLOSED:
            self._done = True
            self.close()
        return state

    async def next(self, timeout: float | None = None) -> ConnectionState:
        """The next state change.

        Raises:
            RosTimeoutError: no change within ``timeout`` seconds.
            ConnectionClosed: the watcher ended (``CLOSED`` was already yielded).
        """
        try:
            async with asyncio.timeout(timeout):
                return await self.__anext__()
        except StopAsyncIteration:
            raise ConnectionClosed("the connection is closed; no more state changes") from None
        except TimeoutError:
            raise RosTimeoutError(f"no connection state change within {timeout} s") from None

    def close(self) -> None:
        """Stop watching."""
        self._done = True
        self._hub._watchers.discard(self)
        if self._waiter is not None and not self._waiter.done():
            self._waiter.set_result(None)

    async def __aenter__(self) -> Self:
        return self

    async def __aexit__(self, *exc: object) -> None:
        self.close()


class StateHub:
    """The connection state and everyone waiting on it (shared by the backends)."""

    def __init__(self, state: ConnectionState) -> None:
        self.state = state
        self._callbacks: list[StateCallback] = []
        self._watchers: set[StateWatcher] = set()
        self._connected_waiters: list[asyncio.Future[None]] = []

    def set(self, state: ConnectionState) -> None:
        """Move to ``state`` and tell every listener (no-op if unchanged)."""
        if state is self.state:
            return
        if log.isEnabledFor(logging.DEBUG):
            log.debug("state %s -> %s", self.state.value, state.value)
        self.state = state
        if state is ConnectionState.CONNECTED or state is ConnectionState.CLOSED:
            waiters, self._connected_waiters = self._connected_waiters, []
            for fut in waiters:
                if not fut.done():
                    fut.set_result(None)
        for watcher in list(self._watchers):
            watcher._push(state)
        for cb in list(self._callbacks):
            try:
                cb(state)
            except Exception:
                log.exception("state callback raised")

    def on_change(self, callback: StateCallback) -> Callable[[], None]:
        """Register ``callback``; returns its remover."""
        return add_callback(self._callbacks, callback)

    def watch(self) -> StateWatcher:
        """A new :class:`StateWatcher`."""
        watcher = StateWatcher(self)
        if not watcher._done:
            self._watchers.add(watcher)
        return watcher

    async def wait_connected(self, timeout: float | None = None) -> None:
        """Return once connected (see :meth:`roslibpy_lite.api.Ros.wait_connected`)."""
        try:
            async with asyncio.timeout(timeout):
                while self.state is not ConnectionState.CONNECTED:
                    if self.state is ConnectionState.CLOSED:
                        raise ConnectionClosed("the connection is closed")
                    fut = asyncio.get_running_loop().create_future()
                    self._connected_waiters.append(fut)
                    await fut
        except TimeoutError:
            raise RosTimeoutError(
                f"not connected within {timeout} s (state {self.state.value})"
            ) from None
