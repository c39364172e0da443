"""What every handle needs from the capability that made it (:class:`Backend`; each
handle's module adds its own hooks: ``PublisherBackend``, ``SubscriptionBackend``,
``ServiceBackend``), and what every handle shares (:class:`_BridgeHandle`: close state,
``await`` and ``async with``)."""

from __future__ import annotations

from collections.abc import Generator
from typing import TYPE_CHECKING, Any, Protocol, Self

if TYPE_CHECKING:
    from types import TracebackType

    from ..exceptions import RosLibError

__all__ = ["Backend"]


class Backend(Protocol):
    """What every handle needs from the capability that made it."""

    async def settle(self, handle: Any) -> None:
        """Return once the handle's request was sent and (if the bridge says so) accepted."""
        ...


class _BridgeHandle:
    """What every handle shares: close state, await and ``async with``."""

    _backend: Backend
    closed: bool
    error: RosLibError | None

    async def close(self) -> None:  # pragma: no cover - overridden
        """Close the handle."""
        raise NotImplementedError

    def fail(self, error: RosLibError) -> None:
        """The bridge reported that this handle's request failed."""
        self.error = error

    async def _ready(self) -> Self:
        await self._backend.settle(self)
        return self

    def __await__(self) -> Generator[Any, None, Self]:
        return self._ready().__await__()

    async def __aenter__(self) -> Self:
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.close()
