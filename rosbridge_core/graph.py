"""The ROS side as the session layer sees it: :class:`Graph`, made of one small port per
capability (:class:`TypesPort`, :class:`IntrospectionPort`, :class:`TopicsPort`,
:class:`ServicesPort`, :class:`ParametersPort`, :class:`ActionsPort`).

The sessions (:mod:`rosbridge_core.session`), the status page (:mod:`bridge_server.http`)
and the ``/rosapi/*`` services hold a :class:`Graph` and never an rclpy object: what
they do to ROS (subscribe, publish, call and serve services, send and serve action
goals, ask the graph what is there, read type definitions) goes through these
methods. Three Graphs take that place without the sessions knowing which:
:class:`bridge_server.rclpy_graph.graph.RclpyGraph`, the Graph on rclpy (the bridge's node,
:class:`~bridge_server.rclpy_graph.node.RosNode`, with its executor thread; the
``rclpy_graph`` package is the only place that imports rclpy),
:class:`bridge_server.zenoh.graph.ZenohGraph`, the relay's Graph on Zenoh, where there is
no ROS, and :class:`rosbridge_core.memory.graph.MemoryGraph`, one node of a whole ROS graph
held in memory (tests, ``MockRos``).

Types are opaque handles: :meth:`Graph.resolve_message` (and its ``srv``/``action``
siblings) give whatever the Graph uses for a type, and the session only passes them
back (to :meth:`Graph.subscribe`, :meth:`Graph.converter`, ...), or reads a service's
``Request``/``Response`` and an action's ``Goal``/``Result``/``Feedback`` parts from
them. Every method is called on the event loop's thread.

Nothing here imports ROS; a test keeps it so.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, Protocol, TypeVar

from rosbridge_core.interfaces import ConversionError, ServiceCallError, args_mapping
from rosbridge_core.protocol.goal_status import GoalStatus

if TYPE_CHECKING:
    from msgs.dynamic import TypeStore
    from rosbridge_core.codec.encodings import Encoded

__all__ = [
    "ACTIVE",
    "CANCEL_ANSWERS",
    "ActionClient",
    "ActionsPort",
    "Converter",
    "GoalListener",
    "Graph",
    "IntrospectionPort",
    "Listener",
    "Message",
    "ParametersPort",
    "Publisher",
    "RosCall",
    "SentGoal",
    "ServedAction",
    "ServedGoal",
    "ServedService",
    "ServicesPort",
    "TopicFeed",
    "TopicsPort",
    "TypesPort",
    "acquire_shared",
    "release_shared",
    "service_request",
    "shared_types",
]


ACTIVE = frozenset({GoalStatus.ACCEPTED, GoalStatus.EXECUTING, GoalStatus.CANCELING})
"""Statuses of a goal that is not finished."""

CANCEL_ANSWERS = {
    1: "the action server refused to cancel it",
    2: "the action server does not know it",
    3: "it had already finished",
}
"""``CancelGoal`` return codes other than 0 (ERROR_NONE), as text."""

class _Counted(Protocol):
    refs: int


_P = TypeVar("_P", bound=_Counted)

PublisherKey = tuple[str, str, bool]
"""What a Graph shares one publisher by: (topic, canonical type, latched)."""


def acquire_shared(publishers: dict[PublisherKey, _P], key: PublisherKey,
                      make: Callable[[], _P]) -> _P:
    """The publisher of ``key`` in a Graph's ``publishers`` (made by ``make`` if there is none
    yet), its reference count raised by one."""
    pub = publishers.get(key)
    if pub is None:
        pub = publishers[key] = make()
    pub.refs += 1
    return pub


def release_shared(publishers: dict[PublisherKey, _P], key: PublisherKey, pub: _P) -> bool:
    """Lower ``pub``'s reference count; at its last reference it leaves ``publishers`` and
    this returns ``True`` (the Graph then tears it down)."""
    pub.refs -= 1
    if pub.refs > 0:
        return False
    if publishers.get(key) is pub:
        del publishers[key]
    return True


def shared_types(publishers: Mapping[PublisherKey, Any], topic: str) -> set[str]:
    """The types of a Graph's own publishers on ``topic``."""
    return {type_name for name, type_name, _ in publishers if name == topic}


def service_request(conv: Converter, service: str, args: Mapping[str, Any] | list[Any] | None,
                    check: Callable[[Any], str | None] | None = None) -> Any:
    """The request message a :meth:`Graph.call_service` sends to ``service``: ``args`` (an
    object, or a list zipped onto the request's fields) built with the request's ``conv``,
    then ``check``-ed; :class:`~rosbridge_core.interfaces.ServiceCallError` names the field
    that does not fit, or gives ``check``'s refusal."""
    try:
        request = conv.from_obj(args_mapping(args, conv.fields, "request"), "args")
    except ConversionError as exc:
        raise ServiceCallError(f"{service}: bad request: {exc}") from None
    refusal = check(request) if check is not None else None  # e.g. an action's cancel_goal
    if refusal is not None:
        raise ServiceCallError(f"{service}: {refusal}")
    return request


class Converter(Protocol):
    """One message type's conversion between the Graph's messages and rosbridge values."""

    @property
    def type_name(self) -> str:
        """Canonical ``pkg/msg/Type``."""

    @property
    def fields(self) -> tuple[str, ...]:
        """Field names in declaration order (a list of ``args`` is zipped onto these)."""

    def to_obj(self, msg: Any) -> dict[str, Any]:
        """The message as a JSON-ready dict."""

    def to_json(self, msg: Any) -> str:
        """The message as compact JSON text."""

    def to_cbor_obj(self, msg: Any) -> Any:
        """The message as a CBOR-ready dict (byte strings, typed arrays)."""

    def from_obj(self, obj: Any, path: str = "") -> Any:
        """A new message from a decoded object; :class:`~rosbridge_core.interfaces.ConversionError`
        names the field (prefixed with ``path``) that does not fit."""


class Message(Protocol):
    """One message received on a topic, encoded for clients lazily and once per encoding
    (:class:`rosbridge_core.codec.encodings.EncodedMessage` is what both ROS sides give)."""

    framed: dict[tuple[str, str | None], Any] | None
    """Its websocket frames by (encoding, topic spelling), made by the first client's
    outbox and shared by the others (:func:`rosbridge_core.session.outbox.shared_frame`)."""

    @property
    def topic(self) -> str:
        """The topic it came on."""

    @property
    def data(self) -> bytes:
        """The message as the ROS side received it: CDR with its 4-byte header, undecoded."""

    @property
    def stamp_ns(self) -> int:
        """When the ROS side received it (nanoseconds since the epoch)."""

    def encoded(self, encoding: str, name: str | None = None) -> Encoded:
        """The whole ``publish`` op in ``encoding`` (``name``: the topic as the client spelt
        it; see :data:`rosbridge_core.codec.encodings.ENCODINGS`)."""

    def json_text(self, name: str | None = None) -> str:
        """The whole ``publish`` op as JSON text."""


Listener = Callable[[Message], None]
"""Called on the event loop with each message of a topic."""


class TopicFeed(Protocol):
    """The Graph's one subscription to a topic, shared by every listening session."""

    topic: str
    msg_cls: Any
    received: int

    @property
    def latched(self) -> Message | None:
        """The last message of a latched (transient local) topic, for a late subscriber."""

    @property
    def type_name(self) -> str | None:
        """Canonical type of the topic, once known."""


class Publisher(Protocol):
    """A publisher shared (reference counted) by the sessions that advertised a topic."""

    @property
    def type_name(self) -> str:
        """Canonical message type."""

    @property
    def conv(self) -> Converter:
        """The topic type's converter."""

    def publish(self, msg: Any) -> None:
        """Publish one message (made with :attr:`conv`, or its CDR bytes)."""


class RosCall(Protocol):
    """A ROS caller waiting for a client-served service's answer."""

    @property
    def request(self) -> Any:
        """The request message."""

    @property
    def served(self) -> ServedService:
        """The service it called."""

    def complete(self, response: Any | None = None) -> bool:
        """Answer the caller (``None``: a default response); False if already answered."""


class ServedService(Protocol):
    """A ROS service whose requests a websocket client answers."""

    @property
    def request_conv(self) -> Converter:
        """Converter of the request."""

    @property
    def response_conv(self) -> Converter:
        """Converter of the response."""

    def destroy(self) -> None:
        """Remove the service from ROS."""


class GoalListener(Protocol):
    """What a sent goal reports to (called on the event loop)."""

    def on_accepted(self) -> None:
        """The action server accepted the goal."""

    def on_rejected(self) -> None:
        """The action server rejected the goal."""

    def on_feedback(self, feedback: Any) -> None:
        """A feedback message."""

    def on_cancel_answer(self, code: int) -> None:
        """The server's answer to a cancel request (0: canceling)."""

    def on_result(self, status: int, result: Any) -> None:
        """The goal ended with ``status`` (a :class:`GoalStatus`) and its result message."""

    def on_failed(self, why: str) -> None:
        """The goal could not be sent, for the reason ``why`` names (a Graph that reaches
        the action server through another process: a relay's)."""


class SentGoal(Protocol):
    """A goal sent through an :class:`ActionClient`."""

    @property
    def shared(self) -> ActionClient:
        """The client it went through."""

    @property
    def handle(self) -> Any:
        """The server's goal handle once it answered (``goal_id.uuid``: the goal's id)."""

    def cancel(self) -> None:
        """Ask the server to cancel it."""


class ActionClient(Protocol):
    """The Graph's client of one action (of one type), shared by every session."""

    name: str
    action_cls: Any

    @property
    def feedback_conv(self) -> Converter:
        """Converter of the action's feedback."""

    @property
    def result_conv(self) -> Converter:
        """Converter of the action's result."""

    def matched(self) -> bool:
        """Whether an action server is matched."""

    def ready(self) -> bool:
        """Whether a goal sent now reaches the server (matched and settled)."""

    def send(self, goal: Any, listener: GoalListener, feedback: bool) -> SentGoal:
        """Send ``goal``; ``listener`` hears what becomes of it."""

    def destroy(self) -> None:
        """Remove the client."""


class ServedGoal(Protocol):
    """A ROS goal that a websocket client serves."""

    @property
    def request(self) -> Any:
        """The goal message."""

    @property
    def served(self) -> ServedAction:
        """The action it is a goal of."""

    def feedback(self, msg: Any) -> None:
        """Publish feedback."""

    def finish(self, status: int, result: Any | None = None) -> bool:
        """End the goal with ``status``; False if it had ended."""


class ServedAction(Protocol):
    """A ROS action server whose goals a websocket client serves."""

    alive: bool

    @property
    def goal_conv(self) -> Converter:
        """Converter of the action's goal."""

    @property
    def feedback_conv(self) -> Converter:
        """Converter of the action's feedback."""

    @property
    def result_conv(self) -> Converter:
        """Converter of the action's result."""

    def destroy(self) -> None:
        """Remove the action server."""


class TypesPort(Protocol):
    """The Graph's port for types: type names resolved, converters, typedefs and
    definitions."""

    @property
    def wire_types(self) -> TypeStore:
        """Where the ``msgs`` classes of this ROS side's types are found and built (CDR
        without rclpy, Foxglove): the process-wide store on rclpy, the robot's own on a
        relay (:mod:`msgs.dynamic`)."""

    def resolve_message(self, name: str) -> Any:
        """The message type named ``pkg/[msg/]Type``; ``TypeNameError``, ``UnknownTypeError``."""

    def resolve_service(self, name: str) -> Any:
        """The service type (``.Request``, ``.Response``) named ``pkg/[srv/]Type``."""

    def resolve_action(self, name: str) -> Any:
        """The action type (``.Goal``, ``.Result``, ``.Feedback``) named ``pkg/[action/]Type``."""

    def converter(self, cls: Any) -> Converter:
        """The converter of a message type (a resolved type or one of its parts)."""

    def typedefs(self, name: str, kind: str, part: str | None = None) -> list[dict[str, Any]]:
        """rosapi typedefs of a type (``part``: ``Request``, ``Goal``, ...) and its nested
        types, each once; ``BridgeError`` naming what is wrong."""

    def installed_interfaces(self) -> list[str]:
        """Every interface type the ROS side has, as ``pkg/<kind>/Name``, sorted."""

    def interface_definition(self, name: str) -> dict[str, Any]:
        """``{"type", "definition"}``: the full definition text of a type, its dependencies'
        after it (the ``ros2msg`` layout); ``BridgeError`` naming what is wrong."""


class IntrospectionPort(Protocol):
    """The Graph's port for introspection: what the ROS graph holds (topics, services,
    nodes, their endpoints, the clock)."""

    def topic_names_and_types(self) -> list[tuple[str, list[str]]]:
        """Every topic in the graph with its types."""

    def service_names_and_types(self) -> list[tuple[str, list[str]]]:
        """Every service in the graph with its types (also names with only clients)."""

    def node_names(self) -> list[tuple[str, str]]:
        """Every node as (name, namespace)."""

    def own_node(self) -> tuple[str, str]:
        """The bridge's own node as (name, namespace)."""

    def node_endpoints(self, name: str, namespace: str) -> tuple[list[str], list[str], list[str]]:
        """Topics a node subscribes to, topics it publishes, services it serves."""

    def node_services(self, name: str, namespace: str) -> list[tuple[str, list[str]]]:
        """Services a node serves, with their types (``Exception`` if the node went)."""

    def topic_publishers(self, topic: str) -> list[tuple[str, str]]:
        """Nodes publishing on ``topic`` as (name, namespace)."""

    def topic_publishers_qos(self, topic: str) -> list[tuple[str, str, dict[str, Any]]]:
        """Publishers of ``topic`` as (name, namespace, offered QoS in rosbag2's keys and
        words: history, depth, reliability, durability, deadline, lifespan, liveliness,
        ...)."""

    def topic_subscribers(self, topic: str) -> list[tuple[str, str]]:
        """Nodes subscribed to ``topic`` as (name, namespace)."""

    def topic_types(self, topic: str) -> list[str]:
        """Types the graph lists for ``topic`` (empty if unknown)."""

    def publisher_types(self, topic: str) -> set[str]:
        """Types of the Graph's own publishers on ``topic``."""

    def service_types(self, service: str) -> list[str]:
        """Types the graph lists for ``service`` (empty if unknown)."""

    def server_count(self, service: str) -> int:
        """How many servers of ``service`` the graph knows."""

    def other_servers(self, service: str) -> list[str]:
        """Servers of ``service`` other than the bridge's own, as text naming each."""

    def server_types(self, service: str) -> list[str]:
        """Types of ``service`` as its servers offer it (the graph's list has clients' too)."""

    def now(self) -> tuple[int, int]:
        """The ROS clock's time as (sec, nanosec)."""


class TopicsPort(Protocol):
    """The Graph's port for topics: shared subscriptions and publishers."""

    @property
    def subscriptions(self) -> Mapping[str, TopicFeed]:
        """The shared subscriptions by topic."""

    @property
    def publishers(self) -> Mapping[tuple[str, str, bool], Publisher]:
        """The shared publishers by (topic, type, latch)."""

    def subscribe(self, topic: str, msg_cls: Any, listener: Listener) -> TopicFeed:
        """Add ``listener`` to the topic's shared subscription (``msg_cls`` None: learn the
        type from the graph); ``ValueError`` if it is subscribed with another type."""

    def unsubscribe(self, shared: TopicFeed, listener: Listener) -> None:
        """Remove ``listener``; the subscription goes with its last listener."""

    def acquire_publisher(self, topic: str, msg_cls: Any, latch: bool, depth: int) -> Publisher:
        """A shared publisher for (topic, type, latch), its reference count raised by one."""

    def release_publisher(self, pub: Publisher) -> None:
        """Lower the reference count; the publisher goes with the last reference."""


class ServicesPort(Protocol):
    """The Graph's port for services: calling them and serving them."""

    async def call_service(
        self, service: str, srv_type: str | None, args: Mapping[str, Any] | list[Any] | None,
        timeout: float, discovery_wait: float,
        check: Callable[[Any], str | None] | None = None,
    ) -> dict[str, Any]:
        """Call ``service`` with the request ``args`` (an object, or a list zipped onto the
        request's fields) and give the response as a dict.

        ``srv_type`` None: the type the graph lists, waited for up to ``discovery_wait`` s;
        ``check`` may refuse the request once it is built (its text says why).
        :class:`~rosbridge_core.interfaces.ServiceCallError` says why there was no answer
        (not in the graph, no server within ``timeout`` s, timed out, a request that does
        not fit); ``TypeNameError``/``UnknownTypeError`` for a bad ``srv_type``.
        """

    def serve(
        self, name: str, srv_cls: Any, on_request: Callable[[RosCall], None],
        on_refused: Callable[[str], None] | None = None,
    ) -> ServedService:
        """Serve ``name`` in ROS; each ROS call is handed to ``on_request`` on the loop.

        ``on_refused`` is called on the loop, at most once, with the reason if the name
        turns out to be served elsewhere after all, so that no call will come (a relay's
        robot keeps another relay's client); the service is then destroyed by the caller.
        ROS itself refuses nothing: the rclpy graph never calls it."""


class ParametersPort(Protocol):
    """The Graph's port for parameters: a node's names, values and setting them."""

    async def parameter_names(self, node: str, timeout: float) -> list[str]:
        """Names of ``node``'s parameters (any failure raises)."""

    async def get_parameter(self, node: str, name: str) -> tuple[bool, Any]:
        """(is set, value) of a node's parameter (as
        :func:`~rosbridge_core.parameters.parameter_value` gives it: a byte array as
        ``bytes``); ``TimeoutError``/``LookupError`` if the node does not answer."""

    async def set_parameter(self, node: str, name: str, value: Any) -> tuple[bool, str]:
        """Set (``None``: unset; ``bytes``: a byte array) a node's parameter: (accepted,
        reason); ``ValueError`` for a value a parameter cannot hold,
        ``TimeoutError``/``LookupError`` as above."""


class ActionsPort(Protocol):
    """The Graph's port for actions: sending goals and serving actions."""

    def action_client(self, name: str, action_cls: Any) -> ActionClient:
        """A new client of action ``name``."""

    def serve_action(
        self, name: str, action_cls: Any, on_goal: Callable[[ServedGoal], None],
        on_cancel: Callable[[ServedGoal], None],
        on_refused: Callable[[str], None] | None = None,
    ) -> ServedAction:
        """Serve action ``name`` in ROS; goals and cancel requests go to the callbacks;
        ``on_refused`` as for :meth:`serve`."""


class Graph(TypesPort, IntrospectionPort, TopicsPort, ServicesPort, ParametersPort,
            ActionsPort, Protocol):
    """The ROS side of the bridge (see the module's text): every port. A session needs
    them all; code that needs fewer names only the ports it uses (rosapi's listings
    :class:`IntrospectionPort` and :class:`TypesPort`, ...)."""

    @property
    def name(self) -> str:
        """The bridge's node name."""

    def trouble(self) -> str | None:
        """Why the ROS side is not serving (``None``: it is)."""
