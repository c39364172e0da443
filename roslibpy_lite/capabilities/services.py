"""Services: call them (``call_service``) and serve them (``advertise_service``).

The handles are in :mod:`roslibpy_lite.handles` (:class:`~roslibpy_lite.handles.ServiceCall`,
:class:`~roslibpy_lite.handles.ServiceServer`).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from rosbridge_core.protocol import ops

from .._api_types import ConnectionState, ServiceHandler
from ..exceptions import RosTimeoutError, ServiceError, UsageError
from ..handles import ServiceCall, ServiceServer
from ..messages import (
    bytes_fixer,
    check_dict,
    check_name,
    from_wire,
    lookup_message_class,
    service_type,
    to_wire,
)
from . import ServingHost, Tracked

if TYPE_CHECKING:
    from msgs.runtime import Message, Service

__all__ = ["Services"]

log = logging.getLogger("roslibpy_lite.client")

_Answer = Mapping[str, Any] | str
"""A service's answer on the wire: its values, or a failure's text."""


class Services:
    """One client's service calls in flight and the services it serves."""

    def __init__(self, host: ServingHost) -> None:
        self.host = host
        self.servers: dict[str, ServiceServer] = {}  # by name, in creation order
        host.route(ops.ServiceResponse, self._on_response)
        host.route(ops.CallService, self._serve_request)
        host.on_restore(self._restore)

    # -- calling -------------------------------------------------------------------------------

    def call(
        self,
        service: str,
        type: str | type[Service],
        args: Mapping[str, Any] | Message | None,
        timeout: float | None,
        wait_connected: bool = False,
        strict: bool | None = None,
    ) -> ServiceCall[Any]:
        """A call to ``service`` (see ``RosBase.call_service``): checked now, sent when awaited."""
        host = self.host
        host.check_open()
        check_name(service, "service")
        type_name, srv_cls = service_type(type)
        what = f"call {service}"
        request_cls = srv_cls.Request if srv_cls else None
        wire = to_wire({} if args is None else args, f"{type_name}_Request", request_cls, what)
        check_cls = request_cls
        if request_cls is None and host.validate:
            check_cls = lookup_message_class(f"{type_name}_Request")
            check_dict(wire, check_cls, what)
        if args is not None and wire is args:  # None asks for the defaults
            host.completeness.check(wire, check_cls, what, strict)
        if timeout is not None and not timeout > 0:
            raise UsageError(f"call {service}: timeout must be > 0 or None, got {timeout!r}")
        return ServiceCall(
            self._call(service, type_name, srv_cls, wire, timeout, wait_connected), service)

    async def _call(
        self,
        service: str,
        type_name: str,
        srv_cls: type[Service] | None,
        wire: Mapping[str, Any],
        timeout: float | None,
        wait_connected: bool,
    ) -> Any:
        host = self.host
        if not wait_connected:
            host.require_link(f"call {service}")
        call_id = host.new_id("call_service", service)
        loop = asyncio.get_running_loop()
        try:
            async with asyncio.timeout(timeout):
                if not host.transport.connected:
                    await host.wait_connected()
                future: asyncio.Future[_Answer] = loop.create_future()
                host.track(call_id, Tracked(service, future=future))
                # The bridge gets a little longer, so our own timeout decides.
                server_timeout = timeout + 1.0 if timeout is not None else None
                host.send(ops.CallService(service, wire, type_name, id=call_id,
                                          timeout=server_timeout))
                values = await future
        except TimeoutError:
            raise RosTimeoutError(
                f"call {service}: no answer within {timeout} s"
                + ("" if host.state is ConnectionState.CONNECTED
                   else f" (state {host.state.value})")
            ) from None
        finally:
            host.untrack(call_id)
        if not isinstance(values, Mapping):  # pragma: no cover - failures are exceptions
            values = {}
        if srv_cls is not None:
            return from_wire(values, srv_cls.Response, f"response of {service}")
        fix = bytes_fixer(f"{type_name}_Response")
        return dict(values if fix is None else fix(values))

    def _on_response(self, op: ops.ServiceResponse) -> None:
        record = self.host.untrack(str(op.id)) if op.id is not None else None
        future = record.future if record is not None else None
        if record is None or future is None:
            log.debug("service_response for an unknown call %r", op.id)
            return
        if future.done():
            return
        if op.result:
            future.set_result(op.values if isinstance(op.values, Mapping) else {})
        else:
            reason = op.values if isinstance(op.values, str) else _reason(op.values)
            future.set_exception(ServiceError(record.name, reason))

    # -- serving -------------------------------------------------------------------------------

    def advertise(
        self, service: str, type: str | type[Service], handler: ServiceHandler
    ) -> ServiceServer:
        """A new served service (see ``RosBase.advertise_service``)."""
        host = self.host
        host.check_open()
        check_name(service, "service")
        type_name, srv_cls = service_type(type)
        if service in self.servers:
            raise UsageError(f"advertise_service {service}: already served by this client")
        server = ServiceServer(self, service, type_name, srv_cls, handler,
                               id=host.new_id("advertise_service", service))
        self.servers[service] = server
        host.request(Tracked(service, handle=server, forget=lambda: self._forget(server)),
                     server.request_op())
        return server

    def _forget(self, server: ServiceServer) -> None:
        if self.servers.get(server.service) is server:
            del self.servers[server.service]

    def forget_service(self, server: ServiceServer) -> None:
        if self.servers.get(server.service) is not server:
            return
        del self.servers[server.service]
        host = self.host
        host.untrack(server.id)
        if host.state is not ConnectionState.CLOSED:
            host.send(ops.UnadvertiseService(server.service, id=server.id))

    async def settle(self, handle: Any) -> None:
        await self.host.settle(handle)

    def _serve_request(self, op: ops.CallService) -> None:
        """A ROS caller's request for a service served here: run the handler, answer."""
        server = self.servers.get(op.service)
        if server is None or op.id is None:
            self.host.send(ops.ServiceResponse(
                op.service, False, f"{op.service} is not served here", id=op.id))
            return
        outcome = server.invoke(op.args)
        if isinstance(outcome, tuple):
            self._answer(op, outcome)
            return

        async def finish() -> None:
            self._answer(op, await outcome)

        self.host.spawn(finish())

    def _answer(self, op: ops.CallService, outcome: tuple[bool, _Answer]) -> None:
        result, values = outcome
        self.host.send_or(ops.ServiceResponse(op.service, result, values, id=op.id),
                          lambda why: ops.ServiceResponse(op.service, False, why, id=op.id))

    # -- the connection ------------------------------------------------------------------------

    def _restore(self) -> None:
        for server in self.servers.values():
            server.error = None
            self.host.send(server.request_op())


def _reason(values: Any) -> str:
    if values is None:
        return "no reason given"
    return str(values)
