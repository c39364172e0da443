"""The services a client of this relay serves on a robot: :class:`ZenohServedService`
(over :class:`ServedHere`, what any name served here declares, which the served actions
share) and :class:`ZenohRosCall`, one ROS call waiting for its answer."""

from __future__ import annotations

import contextlib
import json
import logging
from collections.abc import Callable
from typing import Any

import zenoh

from bridge_server.zenoh import keys
from bridge_server.zenoh.graph.robot import Robot
from bridge_server.zenoh.inbox import direct
from rosbridge_core.graph import RosCall
from rosbridge_core.interfaces import ConversionError, Kind

log = logging.getLogger("bridge_server.zenoh.graph")

__all__ = ["ServedHere", "ZenohRosCall", "ZenohServedService"]


class ZenohRosCall:
    """A ROS caller on the robot waiting for a service this relay's client serves."""

    def __init__(self, served: ZenohServedService, request: Any, query: zenoh.Query) -> None:
        self.served = served
        self.request = request
        self.query: zenoh.Query | None = query

    def complete(self, response: Any | None = None) -> bool:
        """Answer the ROS caller (through the robot); False if already answered."""
        query, self.query = self.query, None
        if query is None:
            return False
        if response is None:
            response = self.served.srv_cls.Response()
        with contextlib.suppress(zenoh.ZError):
            query.reply(query.key_expr, json.dumps(
                self.served.response_conv.to_obj(response), separators=(",", ":")).encode())
        query.drop()  # type: ignore[no-untyped-call]
        return True


class ServedHere:
    """What a client of this relay serves on the robot: the relay's queryable (under
    ``where``) the robot forwards to, a subscriber of the robot's refusal (``@refused``:
    another relay's client serves the name, handed to ``on_refused``), and the ``@serve``
    token that makes the robot serve it in ROS. Declared last (:meth:`_declare`), once the
    subclass can answer."""

    def __init__(self, graph: Robot, name: str,
                 on_refused: Callable[[str], None] | None) -> None:
        self.graph = graph
        self.name = name
        self.on_refused = on_refused
        self._entities: list[Any] = []

    def _declare(self, where: str, type_name: str, kind: Kind) -> None:
        graph = self.graph
        self._entities = [
            graph.session.declare_queryable(
                keys.key_of(graph.robot, self.name, f"{where}/{graph.relay}"),
                direct(graph.on_loop(self._on_query))),
            graph.session.declare_subscriber(
                keys.refused_key(graph.robot, graph.relay, self.name, kind),
                direct(graph.on_loop(self._on_refused))),
            graph.session.liveliness().declare_token(
                keys.serve_key(graph.robot, graph.relay, self.name, type_name, kind)),
        ]

    def _on_refused(self, sample: zenoh.Sample) -> None:
        """The robot does not take this relay's token (on the loop): say why, once."""
        refused, self.on_refused = self.on_refused, None
        if refused is None or not self._entities:
            return
        why = sample.payload.to_string()
        log.warning("robot %s refused this relay's %s: %s", self.graph.robot, self.name, why)
        refused(why)

    def _on_query(self, query: zenoh.Query) -> None:
        raise NotImplementedError

    def _undeclare(self) -> None:
        for entity in self._entities:
            with contextlib.suppress(zenoh.ZError):
                entity.undeclare()
        self._entities.clear()


class ZenohServedService(ServedHere):
    """A service of the robot that a client of this relay serves (``@serving``): each ROS
    call's request comes as a query, the reply answers it."""

    def __init__(self, graph: Robot, name: str, srv_cls: Any,
                 on_request: Callable[[RosCall], None],
                 on_refused: Callable[[str], None] | None = None) -> None:
        super().__init__(graph, name, on_refused)
        self.srv_cls = srv_cls
        self.request_conv = graph.converter(srv_cls.Request)
        self.response_conv = graph.converter(srv_cls.Response)
        self.on_request = on_request
        self._declare(keys.SERVING, srv_cls._type, "srv")

    def _on_query(self, query: zenoh.Query) -> None:
        try:
            obj = json.loads(query.payload.to_bytes() if query.payload else b"")
            request = self.request_conv.from_obj(obj, "request")
        except (ValueError, ConversionError) as exc:
            with contextlib.suppress(zenoh.ZError):
                query.reply_err(f"a request to {self.name} that does not fit: {exc}".encode())
            query.drop()  # type: ignore[no-untyped-call]
            return
        # Not answered (the session failed it or gave up): the query ends when the call is
        # forgotten, and the robot leaves its ROS caller unanswered, as the bridge does.
        self.on_request(ZenohRosCall(self, request, query))

    def destroy(self) -> None:
        """The robot's ROS service goes (with the token)."""
        if self.graph.served.get(self.name) is self:
            del self.graph.served[self.name]
        self._undeclare()
        self.graph.release_types()

