"""A subscription's callbacks (:class:`_Callbacks`): registering them, the task that runs
the async ones in order, and the ones that raise: the first failure of a burst reported in
full, the rest counted into one line per :data:`REPORT_WINDOW` seconds, a callback paused
after :data:`PAUSE_AFTER` failures in a row."""

from __future__ import annotations

import asyncio
import logging
import time
import traceback
from collections.abc import Awaitable, Callable
from typing import Any, TypeVar, cast

from ..._aio import is_async_callable, running_loop
from ..._api_types import MessageCallback
from ...exceptions import UsageError
from ...jupyter import in_cell, write_in_cell
from .fields import _SKIP, _Fields

log = logging.getLogger("roslibpy_lite.client")

T = TypeVar("T")

REPORT_WINDOW = 10.0
"""Seconds over which a failing callback's further failures are counted into one line."""
PAUSE_AFTER = 1000
"""Failures in a row after which a subscription pauses a callback
(:meth:`Subscription.resume_callbacks` runs it again)."""

_STRAY: set[asyncio.Task[None]] = set()
"""Tasks of sync-looking callbacks that returned an awaitable (kept until they end)."""


class _Failures:
    """One callback's failures on one subscription: the first of a burst is reported in
    full, the others counted into one line per :data:`REPORT_WINDOW` seconds."""

    __slots__ = ("callback", "in_row", "last", "more", "since", "timer")

    def __init__(self, callback: Callable[[Any], Any]) -> None:
        self.callback = callback
        self.in_row = 0  # failures since its last success
        self.more = 0  # failures of this burst not reported yet
        self.since = 0.0  # when this window of the burst began (0: no burst)
        self.last = ""  # the last failure, "Type: text"
        self.timer: asyncio.TimerHandle | None = None


def _callback_name(callback: Any) -> str:
    name = getattr(callback, "__qualname__", None)
    return name if isinstance(name, str) else repr(callback)


class _Callbacks(_Fields[T]):
    """Registering callbacks, running the async ones, and the ones that raise."""

    consumer: asyncio.Task[None] | None
    callback_errors: int
    _idle: asyncio.Event
    _failing: dict[int, _Failures]
    paused: list[Callable[[Any], Any]]

    # -- registering ---------------------------------------------------------------------------

    def on_message(self, callback: MessageCallback) -> None:
        """Also deliver every message to ``callback`` (sync or async).

        Once a callback is registered, messages no longer wait for ``async
        for``; sync callbacks run at once in the receive path, async ones in
        order in this subscription's own task.
        """
        if self.closed:
            raise UsageError(f"subscription to {self.topic} is closed")
        if not callable(callback):
            raise UsageError(f"subscribe {self.topic}: callback must be callable")
        callback = in_cell(callback)  # its output under the cell that subscribed, in Jupyter
        if is_async_callable(callback):
            if self._waiter is not None:
                raise UsageError(
                    f"subscription to {self.topic} is being iterated; "
                    "iterate it or give it async callbacks, not both"
                )
            self._async_cbs.append(cast("Callable[[Any], Awaitable[Any]]", callback))
            if self.consumer is None:
                self.consumer = asyncio.get_running_loop().create_task(
                    self._consume(), name=f"roslibpy_lite subscription {self.topic}"
                )
        else:
            self._sync_cbs.append(callback)
        self._buffering = bool(self._async_cbs)

    def remove_callback(self, callback: Any, same: Callable[[Any, Any], bool]) -> Any:
        """Stop calling the registered callback that ``same(it, callback)`` finds; returns
        it (None: there is none). For the topics capability's duplicate rule."""
        for cbs in (self._sync_cbs, self._async_cbs):
            for cb in cbs:
                if same(cb, callback):
                    cbs.remove(cb)
                    self._buffering = bool(self._async_cbs)
                    return cb
        return None

    def has_callbacks(self) -> bool:
        """Whether any callback is registered."""
        return bool(self._sync_cbs or self._async_cbs)

    def _run_stray(self, cb: Callable[[Any], Any], awaitable: Awaitable[Any]) -> None:
        async def run() -> None:
            try:
                await awaitable
            except Exception as exc:
                self._callback_failed(cb, exc)
            else:
                if self._failing:
                    self._callback_ok(cb)

        task = asyncio.get_running_loop().create_task(run())
        _STRAY.add(task)
        task.add_done_callback(_STRAY.discard)

    # -- callbacks that raise ------------------------------------------------------------------

    def _callback_failed(self, cb: Callable[[Any], Any], exc: Exception) -> None:
        """``cb`` raised ``exc``: count it, report the first of a burst in full and the rest
        as one line per window, pause it after PAUSE_AFTER in a row."""
        self.callback_errors += 1
        failures = self._failing.get(id(cb))
        if failures is None:
            failures = self._failing[id(cb)] = _Failures(cb)
        failures.in_row += 1
        failures.last = f"{type(exc).__name__}: {exc}"
        now = time.monotonic()
        if failures.since == 0.0 or (failures.more == 0 and now - failures.since >= REPORT_WINDOW):
            failures.since = now  # a new burst: this one in full
            self._report(cb, f"callback {_callback_name(cb)} for {self.topic} raised (further "
                             f"failures within {REPORT_WINDOW:g} s are counted, not shown):",
                         exc)
            loop = running_loop()
            if loop is not None and failures.timer is None:
                failures.timer = loop.call_later(REPORT_WINDOW, self._window_ended, failures)
        else:
            failures.more += 1
            if now - failures.since >= REPORT_WINDOW:  # no timer (no loop): count here
                self._summarise(failures)
        if failures.in_row >= PAUSE_AFTER:
            self._pause(failures)

    def _callback_ok(self, cb: Callable[[Any], Any]) -> None:
        failures = self._failing.get(id(cb))
        if failures is not None:
            failures.in_row = 0

    def _window_ended(self, failures: _Failures) -> None:
        failures.timer = None
        if failures.more:
            self._summarise(failures)
            loop = running_loop()
            if loop is not None and not self.closed:
                failures.timer = loop.call_later(REPORT_WINDOW, self._window_ended, failures)
        elif self._failing.get(id(failures.callback)) is failures:
            del self._failing[id(failures.callback)]  # the burst is over

    def _summarise(self, failures: _Failures) -> None:
        """Report the failures counted since the last report, as one line."""
        now = time.monotonic()
        if failures.more:
            n = failures.more
            self._report(failures.callback, (
                f"callback {_callback_name(failures.callback)} for {self.topic} raised {n} more "
                f"time{'s' * (n != 1)} in the last {now - failures.since:.1f} s "
                f"(the last: {failures.last})"))
        failures.more = 0
        failures.since = now

    def _pause(self, failures: _Failures) -> None:
        cb = failures.callback
        self._summarise(failures)
        if failures.timer is not None:
            failures.timer.cancel()
        del self._failing[id(cb)]
        self._sync_cbs = [c for c in self._sync_cbs if c is not cb]  # a new list: the
        self._async_cbs = [c for c in self._async_cbs if c is not cb]  # loop goes on
        self._buffering = bool(self._async_cbs)
        self.paused.append(cb)
        self._report(cb, f"callback {_callback_name(cb)} for {self.topic} raised "
                         f"{failures.in_row} times in a row: paused (sub.resume_callbacks() "
                         "runs it again)")

    def resume_callbacks(self) -> int:
        """Run the callbacks paused after failing :data:`PAUSE_AFTER` times in a row again;
        returns how many."""
        paused, self.paused = self.paused, []
        for cb in paused:
            self.on_message(cb)
        return len(paused)

    def _report(self, cb: Callable[[Any], Any], text: str, exc: Exception | None = None) -> None:
        """Under the cell that subscribed ``cb`` in Jupyter, else on the log."""
        if exc is not None:
            shown = text + "\n" + "".join(traceback.format_exception(exc))
            if not write_in_cell(cb, shown):
                log.error("%s", text, exc_info=exc)
        elif not write_in_cell(cb, text):
            log.warning("%s", text)

    def _end_failures(self) -> None:
        """Closing: say what was counted and not yet reported."""
        for failures in list(self._failing.values()):
            if failures.timer is not None:
                failures.timer.cancel()
            self._summarise(failures)
        self._failing.clear()

    # -- the async callbacks' task -------------------------------------------------------------

    async def _consume(self) -> None:
        queue = self._queue
        while True:
            while queue:
                msg = self._decode(queue.popleft())
                if msg is _SKIP:
                    continue
                for cb in self._async_cbs:
                    try:
                        await cb(msg)
                    except Exception as exc:
                        self._callback_failed(cb, exc)
                    else:
                        if self._failing:
                            self._callback_ok(cb)
            self._idle.set()
            if self.closed:
                return
            await self._wait()

    async def _drained(self) -> None:
        """Return once async callbacks have taken every buffered message (for MockRos.drain)."""
        if self.consumer is not None and not self.consumer.done():
            await self._idle.wait()
