"""What every part of a :class:`~roslibpy_lite.handles.Subscription` shares: its fields
(declared in :class:`_Fields`, set by ``Subscription.__init__``), what its readers ask of
the link (:class:`LinkBackend`), the decode step and the one waiter of its buffer."""

from __future__ import annotations

import asyncio
import logging
from collections import deque
from collections.abc import Awaitable, Callable, Mapping
from typing import Any, Generic, Protocol, TypeVar

from msgs.runtime import Message, ValidationError

from ...exceptions import UsageError
from ...messages import RawMessage
from ..base import Backend, _BridgeHandle

log = logging.getLogger("roslibpy_lite.client")

T = TypeVar("T")
_SKIP: Any = object()
"""What :meth:`_Fields._decode` gives for a message that does not fit its class."""


class LinkBackend(Backend, Protocol):
    """What a subscription's readers ask of the link
    (:class:`~roslibpy_lite.capabilities.topics.Topics`)."""

    def require_link(self, what: str, hint: str = "pass wait_connected=True to wait for it"
                     ) -> None:
        """Raise :class:`~roslibpy_lite.exceptions.NotConnected` (naming the state) unless
        the link is up, :class:`~roslibpy_lite.exceptions.ConnectionClosed` once closed."""
        ...

    def link_note(self) -> str:
        """``""`` while connected, else `` (state reconnecting)`` for an error text."""
        ...

    async def silence_note(self, topic: str) -> str:
        """``"; nothing publishes /Imu in the graph; did you mean '/imu'?"`` or ``""``."""
        ...


class _Fields(_BridgeHandle, Generic[T]):
    """The fields the parts of a subscription share (set by ``Subscription.__init__``), its
    decode step and its buffer's waiter."""

    _backend: LinkBackend
    topic: str
    type_name: str
    msg_cls: type[Message] | None
    received: int
    decode_errors: int
    _queue: deque[Mapping[str, Any] | RawMessage]
    _sync_cbs: list[Callable[[Any], Any]]
    _async_cbs: list[Callable[[Any], Awaitable[Any]]]
    _buffering: bool
    _waiter: asyncio.Future[None] | None
    blocking: bool

    def _decode(self, raw: Mapping[str, Any] | RawMessage) -> Any:
        cls = self.msg_cls
        if cls is None or isinstance(raw, RawMessage):
            return raw
        try:
            return cls.from_json(raw)
        except ValidationError as exc:
            self.decode_errors += 1
            # The field path and expected type only: no payload in the log.
            log.warning("a message on %s does not fit %s: field %s: expected %s",
                        self.topic, cls._type, exc.path or "<message>", exc.expected)
            return _SKIP

    def _wake(self) -> None:
        waiter = self._waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    async def _wait(self) -> None:
        if self._waiter is not None:
            raise UsageError(f"subscription to {self.topic} is already awaited by another task")
        self._waiter = asyncio.get_running_loop().create_future()
        try:
            await self._waiter
        finally:
            self._waiter = None
