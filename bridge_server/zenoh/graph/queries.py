"""The calls of a robot's Graph on the relay (:class:`RobotQueries`): a service call and a
node parameter's list, get and set are each one Zenoh query to the robot (:func:`ask`),
answered by the robot's own ROS calls (:class:`~bridge_server.zenoh.keys.CallRequest`,
:class:`~bridge_server.zenoh.keys.ParamRequest`)."""

from __future__ import annotations

import asyncio
import json
from collections.abc import Callable, Mapping
from typing import Any

import zenoh

from bridge_server.zenoh import keys
from bridge_server.zenoh.graph.robot import Robot
from bridge_server.zenoh.inbox import direct
from bridge_server.zenoh.keys import CallRequest, ParamRequest
from rosbridge_core.graph import service_request
from rosbridge_core.interfaces import BridgeError, ServiceCallError

__all__ = ["PARAM_WAIT", "Refused", "RobotQueries", "ask", "param_query"]

PARAM_WAIT = 5.0
"""Seconds a parameter query waits for the robot beyond the robot's own timeout."""


class Refused(BridgeError):
    """The robot answered a query with an error (the text is its reason)."""


async def ask(graph: Robot, key: str, payload: bytes, timeout: float, what: str) -> bytes:
    """One query to the robot: its reply's payload; ``Refused`` with an error reply's text,
    ``TimeoutError`` naming ``what`` if nothing came."""
    future: asyncio.Future[bytes | None] = graph.loop.create_future()

    def answer(reply: zenoh.Reply) -> None:
        if future.done():
            return
        if reply.ok is not None:
            future.set_result(reply.ok.payload.to_bytes())
        elif reply.err is not None:
            future.set_exception(Refused(reply.err.payload.to_string()))

    def ended() -> None:
        if not future.done():
            future.set_result(None)

    def went() -> None:
        if not future.done():
            future.set_exception(Refused(f"{what}: {graph.went('call')}"))

    try:
        graph.session.get(key, direct(graph.on_loop(answer), graph.inbox.end(ended)),
                          payload=payload, timeout=timeout)
    except zenoh.ZError as exc:  # the relay is closing
        raise Refused(f"{what}: this relay's Zenoh session is closed ({exc})") from None
    graph.in_flight.add(went)
    try:
        data = await future
    finally:
        graph.in_flight.discard(went)
    if data is None:
        raise TimeoutError(f"{what}: {await graph.unanswered('call')}")
    return data


async def param_query(graph: Robot, node: str, request: ParamRequest, timeout: float) -> Any:
    """One parameter query, the robot's exceptions raised again as the bridge's."""
    try:
        data = await ask(graph, keys.key_of(graph.robot, node, keys.PARAM), request.encode(),
                         timeout + PARAM_WAIT, f"parameters of {node}")
    except Refused as exc:
        try:
            err = json.loads(str(exc))
            kind, text = str(err["kind"]), str(err["text"])
        except (ValueError, KeyError, TypeError):
            kind, text = "error", str(exc)
        raise {"timeout": TimeoutError, "lookup": LookupError,
               "value": ValueError}.get(kind, BridgeError)(text) from None
    return request.read_answer(data)


class RobotQueries:
    """The service call and parameter methods of :class:`~.zenoh_graph.ZenohGraph` (a
    mixin, its methods typed on the :class:`~.robot.Robot` they need)."""

    async def call_service(
        self: Robot, service: str, srv_type: str | None,
        args: Mapping[str, Any] | list[Any] | None, timeout: float, discovery_wait: float,
        check: Callable[[Any], str | None] | None = None,
    ) -> dict[str, Any]:
        """One query to the robot, which calls the service itself; ``check`` (an action's
        cancel limited to the session's own goals) is asked here first, with the request
        built from the robot's type of the service."""
        if check is not None:
            type_name = srv_type or next(iter(self.service_types(service)), None)
            if type_name is not None:
                service_request(self.converter(self.resolve_service(type_name).Request),
                                service, args, check)
        request = CallRequest(type=srv_type, args=args, timeout=timeout,
                              discovery_wait=discovery_wait)
        try:
            data = await ask(self, keys.key_of(self.robot, service, f"{keys.CALL}/{self.relay}"),
                             request.encode(), timeout + 2 * discovery_wait + 1.0,
                             f"service {service}")
        except (Refused, TimeoutError) as exc:
            raise ServiceCallError(str(exc)) from None
        return json.loads(data)  # type: ignore[no-any-return]

    async def parameter_names(self: Robot, node: str, timeout: float) -> list[str]:
        """Names of a robot node's parameters."""
        names = await param_query(self, node, ParamRequest("names", timeout=timeout), timeout)
        return [str(n) for n in names]

    async def get_parameter(self: Robot, node: str, name: str) -> tuple[bool, Any]:
        """(is set, value) of a robot node's parameter."""
        is_set, value = await param_query(self, node, ParamRequest("get", name=name), PARAM_WAIT)
        return is_set, value

    async def set_parameter(self: Robot, node: str, name: str, value: Any) -> tuple[bool, str]:
        """Set (``None``: unset) a robot node's parameter: (accepted, reason)."""
        ok, reason = await param_query(self, node, ParamRequest("set", name=name, value=value),
                                       PARAM_WAIT)
        return bool(ok), str(reason)

