"""Services of the in-memory graph: :class:`ServiceServer` (a service in the graph: its node,
type and how it answers), :class:`MemoryServedService` (a service a session serves) and
:class:`MemoryRosCall` (a caller waiting for it)."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from typing import Any, Protocol

from msgs.runtime import Service
from rosbridge_core.codec.msgs_types import MsgsConverter
from rosbridge_core.graph import RosCall

__all__ = ["Handler", "MemoryRosCall", "MemoryServedService", "ServiceServer"]

Handler = Callable[[Any], Awaitable[Any]]
"""How a server answers a request message: with its response message (or raises)."""


class Named(Protocol):
    """A node as a service in the graph names it (:class:`~.graph.MemoryGraph`)."""

    @property
    def name(self) -> str: ...

    @property
    def namespace(self) -> str: ...


class _Registry(Protocol):
    """What a served service needs of the whole graph (:class:`~.graph.MemoryRos`)."""

    def remove_server(self, server: ServiceServer) -> None: ...


class ServingNode(Named, Protocol):
    """What a served service or action needs of its node (:class:`~.graph.MemoryGraph`)."""

    @property
    def loop(self) -> asyncio.AbstractEventLoop: ...

    def converter(self, cls: Any) -> MsgsConverter: ...


class _ServiceNode(ServingNode, Protocol):
    @property
    def ros(self) -> _Registry: ...


class ServiceServer:
    """A service in the graph: its node, type and how it answers."""

    def __init__(self, node: Named, name: str, type_name: str, handler: Handler) -> None:
        self.node = node
        self.name = name
        self.type_name = type_name
        self.handler = handler


class MemoryRosCall:
    """A caller waiting for a service a session serves."""

    def __init__(self, served: MemoryServedService, request: Any,
                 answer: asyncio.Future[Any]) -> None:
        self.served = served
        self.request = request
        self._answer = answer

    def complete(self, response: Any | None = None) -> bool:
        """Answer the caller (``None``: a default response); False if already answered."""
        if self._answer.done():
            return False
        self._answer.set_result(response if response is not None
                                else self.served.srv_cls.Response())
        return True


class MemoryServedService:
    """A service of the graph whose calls go to ``on_request``."""

    def __init__(self, graph: _ServiceNode, name: str, srv_cls: type[Service],
                 on_request: Callable[[RosCall], None]) -> None:
        self.graph = graph
        self.name = name
        self.srv_cls = srv_cls
        self.request_conv = graph.converter(srv_cls.Request)
        self.response_conv = graph.converter(srv_cls.Response)
        self.on_request = on_request
        self.server = ServiceServer(graph, name, srv_cls._type, self._answer)

    async def _answer(self, request: Any) -> Any:
        answer: asyncio.Future[Any] = self.graph.loop.create_future()
        self.on_request(MemoryRosCall(self, request, answer))
        return await answer

    def destroy(self) -> None:
        """Remove the service from the graph (a call in flight stays unanswered)."""
        self.graph.ros.remove_server(self.server)
