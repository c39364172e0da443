"""The front's part of services: :class:`ServicesMixin`, which :class:`~roslibpy_lite.ros.RosFront`
inherits (``call_service``, ``advertise_service``, and the ops they send and receive).

The handles are in :mod:`roslibpy_lite.handles` (:class:`~roslibpy_lite.handles.ServiceCall`,
:class:`~roslibpy_lite.handles.ServiceServer`).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, cast, overload

from . import ops
from .api import DEFAULT_CALL_TIMEOUT, ConnectionState, ServiceHandler
from .exceptions import ProtocolError, RosTimeoutError, ServiceError, UsageError
from .handles import ServiceCall, ServiceServer
from .messages import check_dict, check_name, from_wire, lookup_message_class, service_type, to_wire

if TYPE_CHECKING:
    from msgs.runtime import Message, Service

    from .ros import RosFront

__all__ = ["ServicesMixin"]

log = logging.getLogger("roslibpy_lite.client")

_Values = Mapping[str, Any] | str


class _Call:
    """A service call in flight: the service's name and the future its answer settles."""

    __slots__ = ("future", "service")

    def __init__(self, service: str, future: asyncio.Future[_Values]) -> None:
        self.service = service
        self.future = future


class ServicesMixin:
    """The service part of :class:`~roslibpy_lite.ros.RosFront` (it inherits this)."""

    _calls: dict[str, _Call]
    _servers: dict[str, ServiceServer]

    @property
    def _me(self) -> RosFront:
        return cast("RosFront", self)

    def _init_services(self) -> None:
        """Set up the service state and hook it into the front (called by its ``__init__``)."""
        me = self._me
        self._calls = {}  # by request id; status errors naming one fail that call
        self._servers = {}  # by service name, in creation order (restored in that order)
        me._routes[ops.ServiceResponse] = self._on_service_response
        me._routes[ops.CallService] = self._serve_request
        me._restorers.append(self._restore_servers)

    def _restore_servers(self) -> None:
        for server in self._servers.values():
            server.error = None
            self._me._send(server.request_op())

    def _fail_calls(self, error: Callable[[str, str], Exception]) -> None:
        """Fail every call in flight with ``error(service, request_id)``."""
        calls, self._calls = self._calls, {}
        for call_id, call in calls.items():
            if not call.future.done():
                call.future.set_exception(error(call.service, call_id))

    # -- calling -------------------------------------------------------------------------------

    @overload
    def call_service(
        self,
        service: str,
        type: str,
        args: Mapping[str, Any] | None = None,
        *,
        timeout: float | None = DEFAULT_CALL_TIMEOUT,
    ) -> ServiceCall[dict[str, Any]]: ...

    @overload
    def call_service(
        self,
        service: str,
        type: type[Service],
        args: Mapping[str, Any] | Message | None = None,
        *,
        timeout: float | None = DEFAULT_CALL_TIMEOUT,
    ) -> ServiceCall[Any]: ...

    def call_service(
        self,
        service: str,
        type: str | type[Service],
        args: Mapping[str, Any] | Message | None = None,
        *,
        timeout: float | None = DEFAULT_CALL_TIMEOUT,
    ) -> ServiceCall[Any]:
        """Call ``service``; ``await`` the result for its response.

        ``args`` is a dict (or a ``Request`` instance for a typed service);
        the response is a dict, or a ``Response`` instance for a typed
        service. ``timeout`` (seconds, None: wait for ever) covers waiting for
        the connection too. The arguments are checked here, at the call; the
        request is sent when the result is awaited.

        Raises:
            ServiceError: the service answered ``result: false`` (it failed,
                does not exist, or the bridge could not call it); the text says why.
            StatusError: the bridge refused the request itself.
            RosTimeoutError: no answer within ``timeout``.
            Disconnected: the connection dropped while waiting.
            ConnectionClosed: the client is closed.
            UsageError / InvalidMessageError: bad arguments (raised at the call).
        """
        self._me._check_open()
        check_name(service, "service")
        type_name, srv_cls = service_type(type)
        what = f"call {service}"
        request_cls = srv_cls.Request if srv_cls else None
        wire = to_wire({} if args is None else args, f"{type_name}_Request", request_cls, what)
        if request_cls is None and self._me.validate:
            check_dict(wire, lookup_message_class(f"{type_name}_Request"), what)
        if timeout is not None and not timeout > 0:
            raise UsageError(f"call {service}: timeout must be > 0 or None, got {timeout!r}")
        return ServiceCall(self._call(service, type_name, srv_cls, wire, timeout), service)

    async def _call(
        self,
        service: str,
        type_name: str,
        srv_cls: type[Service] | None,
        wire: Mapping[str, Any],
        timeout: float | None,
    ) -> Any:
        me = self._me
        call_id = me._new_id("call_service", service)
        loop = asyncio.get_running_loop()
        try:
            async with asyncio.timeout(timeout):
                if not me._transport.connected:
                    await me._hub.wait_connected()
                future: asyncio.Future[_Values] = loop.create_future()
                self._calls[call_id] = _Call(service, future)
                # The bridge gets a little longer, so our own timeout decides.
                server_timeout = timeout + 1.0 if timeout is not None else None
                me._send(ops.CallService(service, wire, type_name, id=call_id,
                                         timeout=server_timeout))
                values = await future
        except TimeoutError:
            raise RosTimeoutError(
                f"call {service}: no answer within {timeout} s"
                + ("" if me.is_connected else f" (state {me.state.value})")
            ) from None
        finally:
            self._calls.pop(call_id, None)
        if not isinstance(values, Mapping):  # pragma: no cover - failures are exceptions
            values = {}
        if srv_cls is not None:
            return from_wire(values, srv_cls.Response, f"response of {service}")
        return dict(values)

    def _on_service_response(self, op: ops.ServiceResponse) -> None:
        call = self._calls.pop(str(op.id), None) if op.id is not None else None
        if call is None:
            log.debug("service_response for an unknown call %r", op.id)
            return
        if call.future.done():
            return
        if op.result:
            call.future.set_result(op.values if isinstance(op.values, Mapping) else {})
        else:
            reason = op.values if isinstance(op.values, str) else _reason(op.values)
            call.future.set_exception(ServiceError(call.service, reason))

    # -- serving -------------------------------------------------------------------------------

    def advertise_service(
        self, service: str, type: str | type[Service], handler: ServiceHandler
    ) -> ServiceServer:
        """Serve ``service`` to ROS callers with ``handler`` (sync or async).

        The handler gets the request (dict, or ``Request`` instance for a
        typed service) and returns the response (dict, ``Response``, or
        None). If it raises, the caller is answered ``result: false`` with
        the error's text. Use as ``await`` or ``async with``.

        Raises:
            UsageError: a bad name or type, or the service is already served here.
            StatusError: the bridge refused (raised at ``await``; else see :meth:`on_error`).
            ConnectionClosed: the client is closed.
        """
        me = self._me
        me._check_open()
        check_name(service, "service")
        type_name, srv_cls = service_type(type)
        if service in self._servers:
            raise UsageError(f"advertise_service {service}: already served by this client")
        server = ServiceServer(me, service, type_name, srv_cls, handler,
                               id=me._new_id("advertise_service", service))
        self._servers[service] = server
        me._request(server, server.request_op())
        return server

    def _unadvertise_service(self, server: ServiceServer) -> None:
        me = self._me
        if self._servers.get(server.service) is not server:
            return
        del self._servers[server.service]
        me._requests.pop(server.id, None)
        if me._hub.state is not ConnectionState.CLOSED:
            me._send(ops.UnadvertiseService(server.service, id=server.id))

    def _serve_request(self, op: ops.CallService) -> None:
        """A ROS caller's request for a service served here: run the handler, answer."""
        me = self._me
        server = self._servers.get(op.service)
        if server is None or op.id is None:
            me._send(ops.ServiceResponse(op.service, False, f"{op.service} is not served here",
                                         id=op.id))
            return
        outcome = server.invoke(op.args)
        if isinstance(outcome, tuple):
            self._answer(op, outcome)
            return

        async def finish() -> None:
            self._answer(op, await outcome)

        task = asyncio.get_running_loop().create_task(finish())
        me._handler_tasks.add(task)
        task.add_done_callback(me._handler_tasks.discard)

    def _answer(self, op: ops.CallService, outcome: tuple[bool, _Values]) -> None:
        result, values = outcome
        t = self._me._transport
        if not t.connected:
            return
        try:
            frame = t.encode(ops.ServiceResponse(op.service, result, values, id=op.id))
        except ProtocolError as exc:
            frame = t.encode(ops.ServiceResponse(op.service, False, exc.message, id=op.id))
        t.write(frame)


def _reason(values: Any) -> str:
    if values is None:
        return "no reason given"
    return str(values)
