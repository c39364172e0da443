"""Reading a subscription (:class:`_Reading`): its buffer (``async for``, :meth:`get`) and
fresh messages apart from it (:meth:`latest`, :meth:`next`, :meth:`collect`, through
:class:`_Tap`), with what they give (:class:`Latest`, :class:`Collected`)."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Mapping
from typing import Any, Generic, NamedTuple, Self, TypeVar

from ...exceptions import NoMessageYet, RosLibWarning, RosTimeoutError, UsageError
from ...messages import RawMessage, warn_user
from .fields import _SKIP, _Fields

T = TypeVar("T")

_HINTS = {"next": "await sub.next(timeout) waits for one",
          "wait_connected": "await ros.wait_connected() first"}


class Latest(NamedTuple, Generic[T]):
    """The newest message of a subscription and how old it is (:meth:`Subscription.latest`).

    Unpacks as ``msg, age = sub.latest()``.
    """

    msg: T
    """The message, as the subscription gives it (dict, typed instance or RawMessage)."""
    age: float
    """Seconds since this client received it (when :meth:`Subscription.latest` was called)."""

    @property
    def stamp_age(self) -> float | None:
        """Seconds from the message's ``header.stamp`` to now, by this machine's clock (so
        it includes any offset between the robot's clock and this one, and a simulated
        clock's stamps give nonsense); None for a message without a header stamp."""
        stamp = _header_stamp(self.msg)
        return None if stamp is None else time.time() - stamp


def _header_stamp(msg: Any) -> float | None:
    """``header.stamp`` in seconds since the epoch, of a dict or typed message (None: none)."""
    if isinstance(msg, Mapping):
        stamp = (msg.get("header") or {}).get("stamp")
        sec, nanosec = (stamp.get("sec"), stamp.get("nanosec")) if isinstance(
            stamp, Mapping) else (None, None)
    else:
        stamp = getattr(getattr(msg, "header", None), "stamp", None)
        sec, nanosec = getattr(stamp, "sec", None), getattr(stamp, "nanosec", None)
    if not isinstance(sec, int) or not isinstance(nanosec, int):
        return None
    return sec + nanosec / 1e9


class Collected(list[T]):
    """The messages :meth:`Subscription.collect` received, oldest first: a list, with
    :attr:`times` beside it (``roslibpy_lite.data.to_dataframe`` indexes by them when the
    messages have no header stamp)."""

    def __init__(self, messages: list[T], times: list[float]) -> None:
        super().__init__(messages)
        self.times = times
        """When each message was received (seconds since the epoch)."""


class _Tap:
    """A reader of fresh messages (``next`` or ``collect``): sees each message delivered
    from its start on, apart from the buffer."""

    __slots__ = ("future", "messages", "times", "wait_connected")

    def __init__(self, future: asyncio.Future[None] | None, wait_connected: bool) -> None:
        self.future = future
        self.wait_connected = wait_connected
        self.messages: list[Any] = []
        self.times: list[float] = []


class _Reading(_Fields[T]):
    """The buffer's readers and the fresh-message readers."""

    _latest: Mapping[str, Any] | RawMessage | None
    _latest_at: float
    _since: float
    _taps: list[_Tap]
    held_warnings: list[Warning]
    collected: Collected[T]

    def __aiter__(self) -> Self:
        return self

    async def __anext__(self) -> T:
        queue = self._queue
        while True:
            if queue:
                msg = self._decode(queue.popleft())
                if msg is _SKIP:
                    continue
                result: T = msg
                return result
            if self.error is not None:
                raise self.error
            if self.closed:
                raise StopAsyncIteration
            if self._async_cbs:
                raise UsageError(
                    f"subscription to {self.topic} delivers to async callbacks; "
                    "iterate it or give it callbacks, not both"
                )
            await self._wait()

    async def get(self, timeout: float | None = None) -> T:
        """The OLDEST message waiting in this subscription's buffer, or, when it is empty,
        the next one to arrive: what ``async for`` gives next.

        Nothing is skipped, so a message read a while after subscribing may be seconds old
        (up to ``buffer_size`` messages wait; see the "Buffers" section of the Publish and
        subscribe guide). For the newest message use :meth:`latest`, for one that arrives
        after the call :meth:`next`.

        Raises:
            RosTimeoutError: none arrived within ``timeout`` seconds (the text names the
                connection state when the link is down).
            UsageError: the subscription is closed.
            StatusError: the bridge refused this subscription.
        """
        try:
            async with asyncio.timeout(timeout):
                return await self.__anext__()
        except StopAsyncIteration:
            raise UsageError(f"subscription to {self.topic} is closed") from None
        except TimeoutError:
            raise await self._silence(timeout) from None

    def latest(self, *, allow_stale: bool = False) -> Latest[T]:
        """The newest message received (whatever the buffer holds) and its age in seconds
        since this client received it (``.stamp_age``: since its header stamp).

        Reads without waiting and takes nothing from the buffer. ``allow_stale=True`` also
        answers while the link is down (the age then says how stale it is).

        Raises:
            NotConnected: the link is down (the text names the state); the message would
                be from before the outage.
            NoMessageYet: nothing has arrived yet (``await sub.next(timeout)`` waits).
            UsageError: the subscription is closed.
            StatusError: the bridge refused this subscription.
        """
        self._check_readable()
        if not allow_stale:
            self._backend.require_link(f"latest message on {self.topic}",
                                       "latest(allow_stale=True) reads it anyway")
        raw = self._latest
        if raw is None:
            raise NoMessageYet(
                f"no message on {self.topic} yet (subscribed "
                f"{time.monotonic() - self._since:.1f} s ago); {self._hint('next')}"
            )
        msg = self._decode(raw)
        if msg is _SKIP:
            raise NoMessageYet(f"the latest message on {self.topic} did not fit "
                               f"{self.type_name} (see the log)")
        return Latest(msg, time.monotonic() - self._latest_at)

    async def next(self, timeout: float | None = None, *, wait_connected: bool = False) -> T:
        """The first message to arrive after this call (the buffer is left as it is).

        ``wait_connected=True``: while the link is down, wait for it (within ``timeout``)
        instead of raising.

        Raises:
            NotConnected: the link is down, or drops while waiting (unless ``wait_connected``).
            RosTimeoutError: none arrived within ``timeout`` seconds.
            UsageError: the subscription is closed.
            StatusError: the bridge refused this subscription.
        """
        self._check_readable()
        if not wait_connected:
            self._backend.require_link(f"next message on {self.topic}")
        tap = _Tap(asyncio.get_running_loop().create_future(), wait_connected)
        self._taps.append(tap)
        try:
            async with asyncio.timeout(timeout):
                while True:
                    assert tap.future is not None
                    await tap.future
                    while tap.messages:
                        msg = self._decode(tap.messages.pop(0))
                        if msg is not _SKIP:
                            result: T = msg
                            return result
                    tap.future = asyncio.get_running_loop().create_future()
        except TimeoutError:
            self._taps.remove(tap)
            raise await self._silence(timeout) from None
        finally:
            if tap in self._taps:
                self._taps.remove(tap)

    async def collect(self, seconds: float) -> Collected[T]:
        """Every message that arrives during the next ``seconds`` seconds, oldest first,
        with when each arrived (:class:`Collected`; the buffer is left as it is).

        Interrupted (cancelled, Ctrl+C, a notebook's stop button), it keeps what it had
        collected in :attr:`collected`.

        Raises:
            NotConnected: the link is down when it starts.
            UsageError: ``seconds`` is negative, or the subscription is closed.
        """
        if not seconds >= 0:
            raise UsageError(f"collect from {self.topic}: seconds must be >= 0, got {seconds!r}")
        self._check_readable()
        self._backend.require_link(f"collect from {self.topic}", self._hint("wait_connected"))
        tap = _Tap(None, True)
        self._taps.append(tap)
        try:
            await asyncio.sleep(seconds)  # a window of time is what was asked for
        except asyncio.CancelledError as exc:  # a notebook's stop button, a task's cancel
            exc.add_note(f"collect from {self.topic} was interrupted: the "
                         f"{len(tap.messages)} messages it had are in sub.collected")
            raise
        finally:
            self._taps.remove(tap)
            messages: list[T] = []
            times: list[float] = []
            for raw, when in zip(tap.messages, tap.times, strict=True):
                msg = self._decode(raw)
                if msg is not _SKIP:
                    messages.append(msg)
                    times.append(when)
            self.collected = Collected(messages, times)
        if not self.collected and (note := await self._backend.silence_note(self.topic)):
            warning = RosLibWarning(f"collect from {self.topic}: no message in {seconds} s{note}")
            if self.blocking:
                self.held_warnings.append(warning)  # given on the caller's thread
            else:
                warn_user(warning)
        return self.collected

    async def _silence(self, timeout: float | None) -> RosTimeoutError:
        """The error of a wait that ended empty, naming a misspelt topic."""
        note = self._backend.link_note() or await self._backend.silence_note(self.topic)
        return RosTimeoutError(f"no message on {self.topic} within {timeout} s{note}")

    def _hint(self, kind: str) -> str:
        """The call that helps (``next``, ``wait_connected``), spelt for this handle's client."""
        text = _HINTS[kind]
        return text.removeprefix("await ") if self.blocking else text

    def _check_readable(self) -> None:
        if self.error is not None:
            raise self.error
        if self.closed:
            raise UsageError(f"subscription to {self.topic} is closed")

    @property
    def pending(self) -> int:
        """How many messages wait in the buffer."""
        return len(self._queue)
