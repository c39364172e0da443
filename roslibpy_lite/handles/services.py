"""Services: one served by this client (:class:`ServiceServer`, made by
``ros.advertise_service``) and a call's awaitable (:class:`ServiceCall`, what
``ros.call_service`` returns)."""

from __future__ import annotations

import inspect
import logging
from collections.abc import Awaitable, Coroutine, Mapping
from typing import Any, Protocol, TypeVar

from msgs.runtime import Message, Service
from rosbridge_core.protocol import ops

from .._api_types import ServiceHandler
from ..exceptions import InvalidMessageError, RosLibError, UsageError
from ..messages import from_wire, to_wire
from .awaitables import _Deferred, _NotAwaited
from .base import Backend, _BridgeHandle

log = logging.getLogger("roslibpy_lite.client")

T = TypeVar("T")
_Outcome = tuple[bool, Mapping[str, Any] | str]


class ServiceBackend(Backend, Protocol):
    """What a served service needs (:class:`~roslibpy_lite.capabilities.services.Services`)."""

    def forget_service(self, server: ServiceServer) -> None:
        """Forget a served service."""
        ...


class ServiceServer(_BridgeHandle):
    """A service served by this client (made by ``ros.advertise_service``)."""

    _backend: ServiceBackend

    def __init__(
        self,
        backend: ServiceBackend,
        service: str,
        type_name: str,
        srv_cls: type[Service] | None,
        handler: ServiceHandler,
        *,
        id: str,
    ) -> None:
        if not callable(handler):
            raise UsageError(f"advertise_service {service}: handler must be callable")
        self._backend = backend
        self.service = service
        self.type_name = type_name
        self.srv_cls = srv_cls
        self.handler = handler
        self.id = id
        self.closed = False
        self.error: RosLibError | None = None
        self.calls = 0
        """Requests handled."""
        self.failures = 0
        """Requests whose handler raised (answered ``result: false``)."""

    def __repr__(self) -> str:
        return f"<ServiceServer {self.service} {self.type_name}{' closed' if self.closed else ''}>"

    def request_op(self) -> ops.AdvertiseService:
        """The ``advertise_service`` op this server stands for."""
        return ops.AdvertiseService(self.service, self.type_name, id=self.id)

    def invoke(self, args: Any) -> _Outcome | Coroutine[Any, Any, _Outcome]:
        """Run the handler on a request's wire form.

        Returns ``(result, values)`` at once for a sync handler, or a
        coroutine that produces it for an async one. A handler that raises,
        a request that does not fit the type, or a response that does not fit,
        gives ``(False, "<text>")``; ``(True, values)`` otherwise.
        """
        self.calls += 1
        try:
            request = self._request(args)
            result = self.handler(request)
        except Exception as exc:
            return self._failed(exc)
        if inspect.isawaitable(result):
            return self._finish(result)
        return self._response(result)

    async def _finish(self, awaitable: Awaitable[Any]) -> tuple[bool, Mapping[str, Any] | str]:
        try:
            result = await awaitable
        except Exception as exc:
            return self._failed(exc)
        return self._response(result)

    def _request(self, args: Any) -> Any:
        if args is None:
            args = {}
        if not isinstance(args, Mapping):
            raise InvalidMessageError(f"request to {self.service} is not an object")
        if self.srv_cls is None:
            return args
        return from_wire(args, self.srv_cls.Request, f"request to {self.service}")

    def _response(self, result: Any) -> tuple[bool, Mapping[str, Any] | str]:
        try:
            if result is None:
                result = self.srv_cls.Response() if self.srv_cls is not None else {}
            cls = self.srv_cls.Response if self.srv_cls is not None else None
            type_name = cls._type if cls is not None else f"{self.type_name}_Response"
            what = f"response of {self.service}"
            wire = to_wire(result, type_name, cls, what)
            if cls is not None and not isinstance(result, Message):
                from_wire(wire, cls, what)  # a dict answer to a typed service must fit too
            return True, wire
        except Exception as exc:
            return self._failed(exc)

    def _failed(self, exc: Exception) -> tuple[bool, str]:
        self.failures += 1
        # The class and text say what went wrong; the request itself is not logged.
        log.warning("handler of %s raised %s: %s", self.service, type(exc).__name__, exc)
        return False, str(exc) or type(exc).__name__

    async def unadvertise(self) -> None:
        """Stop serving."""
        if self.closed:
            return
        self.closed = True
        self._backend.forget_service(self)

    async def close(self) -> None:
        """Same as :meth:`unadvertise`."""
        await self.unadvertise()


class ServiceCall(_Deferred[T]):
    """What ``ros.call_service(...)`` returns: ``await`` it for the response.

    Used without ``await`` (indexed, its attributes read, iterated, or
    dropped) it raises (or logs) :class:`~roslibpy_lite.exceptions.UsageError`
    saying "did you forget await?".
    """

    __slots__ = ()

    def __init__(self, coro: Coroutine[Any, Any, T], service: str) -> None:
        super().__init__(coro, f"call_service({service!r})")

    def _unawaited(self) -> UsageError:
        return _NotAwaited(
            f"{self._what} returns an awaitable, not the response: did you forget await? "
            f"(reply = await ros.call_service(...))"
        )

    def __getattr__(self, name: str) -> Any:
        raise self._unawaited()

    def __getitem__(self, key: Any) -> Any:
        raise self._unawaited()

    def __iter__(self) -> Any:
        raise self._unawaited()

    def __bool__(self) -> bool:
        raise self._unawaited()
