"""The :class:`~rosbridge_core.graph.Graph` on rclpy: the bridge's node with what the
sessions ask of the ROS side that is not about the node's own entities.

:class:`RclpyGraph` is :class:`~.node.RosNode` (the node, its executor thread, shared
subscriptions, publishers, service clients and servers) plus the graph's questions
(topics, services, nodes and their endpoints), typed service calls, node parameters,
action clients and servers (:mod:`.actions`) and type definitions (:mod:`.introspection`).
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Mapping
from typing import Any

from bridge_server.rclpy_graph import convert, introspection
from bridge_server.rclpy_graph.actions import (
    ServedAction,
    ServedGoal,
    SharedActionClient,
    check_rclpy_internals,
)
from bridge_server.rclpy_graph.node import RosNode
from bridge_server.rclpy_graph.types import installed_interfaces, resolve_action
from rosbridge_core.graph import service_request
from rosbridge_core.interfaces import ServiceCallError

__all__ = ["RclpyGraph"]


class RclpyGraph(RosNode):
    """The ROS side of the bridge on rclpy (all of :class:`~rosbridge_core.graph.Graph`)."""

    def start(self) -> None:
        """Check rclpy's internals the actions use (a clear error now, not a crash at the
        first goal), then start the node."""
        check_rclpy_internals()
        super().start()

    def trouble(self) -> str | None:
        """Why the ROS side is not serving (``None``: it is)."""
        if self.node is None or not self.context.ok():
            return "rclpy is not running"
        if self._thread is None or not self._thread.is_alive():
            return "the ROS executor thread is not running"
        return None

    # -- graph ---------------------------------------------------------------------------------

    def topic_names_and_types(self) -> list[tuple[str, list[str]]]:
        """Every topic in the graph with its types."""
        return [(n, list(ts)) for n, ts in self.node.get_topic_names_and_types()]

    def service_names_and_types(self) -> list[tuple[str, list[str]]]:
        """Every service in the graph with its types (also names that only have clients)."""
        return [(n, list(ts)) for n, ts in self.node.get_service_names_and_types()]

    def node_names(self) -> list[tuple[str, str]]:
        """Every node as (name, namespace)."""
        return list(self.node.get_node_names_and_namespaces())

    def own_node(self) -> tuple[str, str]:
        """The bridge's own node as (name, namespace)."""
        return self.node.get_name(), self.node.get_namespace()

    def node_endpoints(self, name: str, namespace: str) -> tuple[list[str], list[str], list[str]]:
        """Topics a node subscribes to, topics it publishes, services it serves."""
        node = self.node
        subs = [t for t, _ in node.get_subscriber_names_and_types_by_node(name, namespace)]
        pubs = [t for t, _ in node.get_publisher_names_and_types_by_node(name, namespace)]
        srvs = [s for s, _ in node.get_service_names_and_types_by_node(name, namespace)]
        return subs, pubs, srvs

    def node_services(self, name: str, namespace: str) -> list[tuple[str, list[str]]]:
        """Services a node serves with their types (raises if the node went meanwhile)."""
        return [(s, list(ts)) for s, ts in
                self.node.get_service_names_and_types_by_node(name, namespace)]

    def topic_publishers(self, topic: str) -> list[tuple[str, str]]:
        """Nodes publishing on ``topic`` as (name, namespace)."""
        return [(i.node_name, i.node_namespace)
                for i in self.node.get_publishers_info_by_topic(topic)]

    def topic_publishers_qos(self, topic: str) -> list[tuple[str, str, dict[str, Any]]]:
        """Publishers of ``topic`` with the QoS each offers, in rosbag2's keys and words (the
        graph reports no history: "unknown", depth 0, as rosbag2 records it too)."""
        found = []
        for info in self.node.get_publishers_info_by_topic(topic):
            q = info.qos_profile
            found.append((info.node_name, info.node_namespace, {
                "history": _policy(q.history),
                "depth": int(q.depth),
                "reliability": _policy(q.reliability),
                "durability": _policy(q.durability),
                "deadline": _duration(q.deadline),
                "lifespan": _duration(q.lifespan),
                "liveliness": _policy(q.liveliness),
                "liveliness_lease_duration": _duration(q.liveliness_lease_duration),
                "avoid_ros_namespace_conventions": bool(q.avoid_ros_namespace_conventions),
            }))
        return found

    def topic_subscribers(self, topic: str) -> list[tuple[str, str]]:
        """Nodes subscribed to ``topic`` as (name, namespace)."""
        return [(i.node_name, i.node_namespace)
                for i in self.node.get_subscriptions_info_by_topic(topic)]

    def server_types(self, service: str) -> list[str]:
        """Types of ``service`` as its servers offer it (the graph's own list has clients'
        too)."""
        node = self.node
        found: list[str] = []
        for n, ns in node.get_node_names_and_namespaces():
            try:
                served = node.get_service_names_and_types_by_node(n, ns)
            except Exception:  # the node went away meanwhile
                continue
            found += [t for s, types in served if s == service for t in types if t not in found]
        if not found and node.count_services(service):
            # A server's endpoint reaches the graph before its node's name does (seconds before
            # on a busy machine): until then its types are the graph's own for the name.
            found = [t for s, types in node.get_service_names_and_types() if s == service
                     for t in types]
        return found

    # -- services ------------------------------------------------------------------------------

    async def call_service(
        self, service: str, srv_type: str | None, args: Mapping[str, Any] | list[Any] | None,
        timeout: float, discovery_wait: float,
        check: Callable[[Any], str | None] | None = None,
    ) -> dict[str, Any]:
        """Call ``service`` with the request ``args``; the response as a dict.

        ``srv_type`` None: the type the graph lists, waited for up to ``discovery_wait`` s.
        ``check`` may refuse the converted request (its text is the refusal).
        :class:`~rosbridge_core.interfaces.ServiceCallError` says why there was no answer.
        """
        loop = self.loop
        deadline = loop.time() + timeout
        if srv_type is not None:
            srv_cls = self.resolve_service(srv_type)
        else:
            types = self.service_types(service)
            if not types:
                wait_until = min(deadline, loop.time() + discovery_wait)
                while not types and loop.time() < wait_until:
                    await asyncio.sleep(0.02)
                    types = self.service_types(service)
            if not types:
                raise ServiceCallError(f"service {service} does not exist (not in the ROS graph)")
            srv_cls = self.resolve_service(types[0])
        request = service_request(convert.converter_for(srv_cls.Request), service, args, check)
        # Wait for a server to be discovered and matched: while the graph lists no server, at
        # most twice discovery_wait (a server that was just started can take ~3 s to show on
        # a loaded machine); once it does, up to the call's timeout.
        unlisted_wait = 2 * discovery_wait
        try:
            client = await self.wait_for_server(service, srv_cls, deadline,
                                                loop.time() + unlisted_wait)
        except LookupError:
            self.drop_client(service, srv_cls)  # so the graph forgets the name
            raise ServiceCallError(
                f"service {service} does not exist (not in the ROS graph after "
                f"{unlisted_wait:g} s)"
            ) from None
        except TimeoutError:
            self.drop_client(service, srv_cls)  # so the graph forgets the name
            if self.server_count(service) == 0:
                raise ServiceCallError(
                    f"service {service} does not exist (no server appeared within {timeout} s)"
                ) from None
            raise ServiceCallError(
                f"service {service} did not become available in {timeout} s"
            ) from None
        await self.settled(client)  # a newly matched server may not hear back yet
        # A timer that fails the future is cheaper than asyncio.wait_for (no extra task).
        future = self.call(client, request)
        timer = loop.call_at(deadline, _expire, future)
        try:
            response = await future
        except _Expired:
            raise ServiceCallError(f"service {service} timed out after {timeout} s") from None
        finally:
            timer.cancel()
            if not future.done():  # this task was cancelled: forget the request
                future.cancel()
        return convert.converter_for(srv_cls.Response).to_obj(response)

    # -- parameters ----------------------------------------------------------------------------

    async def parameter_names(self, node: str, timeout: float) -> list[str]:
        """Names of ``node``'s parameters (any failure raises)."""
        return await introspection.parameter_names(self, node, timeout)

    async def get_parameter(self, node: str, name: str) -> tuple[bool, Any]:
        """(is set, value) of one parameter of ``node``."""
        return await introspection.get_parameter(self, node, name)

    async def set_parameter(self, node: str, name: str, value: Any) -> tuple[bool, str]:
        """Set (``None``: unset) one parameter of ``node``: (accepted, reason)."""
        return await introspection.set_parameter(self, node, name, value)

    # -- actions -------------------------------------------------------------------------------

    def action_client(self, name: str, action_cls: type[Any]) -> SharedActionClient:
        """A new client of action ``name`` (:mod:`.actions`)."""
        return SharedActionClient(self, name, action_cls)

    def serve_action(
        self, name: str, action_cls: type[Any], on_goal: Callable[[ServedGoal], None],
        on_cancel: Callable[[ServedGoal], None],
        on_refused: Callable[[str], None] | None = None,
    ) -> ServedAction:
        """Serve action ``name`` in ROS (:mod:`.actions`); ``on_refused`` is never called
        (ROS refuses no name)."""
        return ServedAction(self, name, action_cls, on_goal, on_cancel)

    # -- types ---------------------------------------------------------------------------------

    @staticmethod
    def resolve_action(name: str) -> type[Any]:
        """The action class for a type string (both spellings)."""
        return resolve_action(name)

    @staticmethod
    def converter(cls: type[Any]) -> convert.Converter:
        """The converter of a message class (:mod:`.convert`)."""
        return convert.converter_for(cls)

    @staticmethod
    def typedefs(name: str, kind: str, part: str | None = None) -> list[dict[str, Any]]:
        """rosapi typedefs of a type and its nested types (:mod:`.introspection`)."""
        return introspection.typedefs(name, kind, part)

    @staticmethod
    def installed_interfaces() -> list[str]:
        """Every interface type installed with the bridge (:mod:`.types`)."""
        return installed_interfaces()

    @staticmethod
    def interface_definition(name: str) -> dict[str, Any]:
        """The full definition text of an installed type (:mod:`.introspection`)."""
        return introspection.interface_definition(name)


class _Expired(Exception):
    """A ROS service call ran out of time."""


def _expire(future: asyncio.Future[Any]) -> None:
    if not future.done():
        future.set_exception(_Expired())


def _duration(value: Any) -> dict[str, int]:
    sec, nsec = divmod(int(value.nanoseconds), 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


def _policy(value: Any) -> str:
    return str(getattr(value, "name", value)).lower()  # rmw's words: keep_last, reliable...
