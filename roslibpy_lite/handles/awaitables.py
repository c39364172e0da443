"""Awaitables that refuse to be used un-awaited: a publish's result (:data:`_DONE`, a
finished coroutine, or :class:`_Deferred`, which logs "did you forget await?" when dropped
unstarted); :class:`~roslibpy_lite.handles.services.ServiceCall` builds on the latter."""

from __future__ import annotations

import logging
from collections.abc import Coroutine, Generator
from typing import Any, TypeVar

from ..exceptions import UsageError

log = logging.getLogger("roslibpy_lite.client")

T = TypeVar("T")


class _Done(Coroutine[Any, None, None]):
    """The result of a publish that needs no waiting: a finished coroutine (stateless)."""

    __slots__ = ()

    def __await__(self) -> Generator[Any, None, None]:
        return
        yield  # pragma: no cover - makes this a generator

    def send(self, value: Any) -> Any:
        """Finish at once."""
        raise StopIteration

    def throw(self, *args: Any) -> Any:
        """Raise the given exception."""
        exc = args[1] if len(args) > 1 and args[1] is not None else args[0]
        raise exc

    def close(self) -> None:
        """Nothing to close."""


_DONE = _Done()


class _Deferred(Coroutine[Any, Any, T]):
    """A coroutine wrapper that says "did you forget await?" if it is dropped unstarted.

    It is a real :class:`collections.abc.Coroutine`, so ``asyncio.create_task``
    and ``gather`` take it like the coroutine it wraps.
    """

    __slots__ = ("_coro", "_started", "_what")

    def __init__(self, coro: Coroutine[Any, Any, T], what: str) -> None:
        self._coro = coro
        self._what = what
        self._started = False

    def __await__(self) -> Generator[Any, None, T]:
        self._started = True
        return self._coro.__await__()

    def send(self, value: Any) -> Any:
        """Advance the wrapped coroutine (what a Task does)."""
        self._started = True
        return self._coro.send(value)

    def throw(self, *args: Any) -> Any:
        """Raise inside the wrapped coroutine."""
        self._started = True
        return self._coro.throw(*args)

    def close(self) -> None:
        """Close the wrapped coroutine."""
        self._started = True
        self._coro.close()

    def __del__(self) -> None:
        if not self._started:
            self._coro.close()
            log.error("%s was never awaited: did you forget await?", self._what)


class _NotAwaited(UsageError, AttributeError):
    """An awaitable used as its result (an AttributeError too, so ``getattr(x, n, d)`` works)."""
