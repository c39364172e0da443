"""MockRos: the :class:`~roslibpy_lite.api.Ros` API in memory, for users' unit tests.

No network and no ROS: MockRos is the same RosBase as the websocket
:class:`~roslibpy_lite.client.Client` (:class:`~roslibpy_lite.ros.RosBase`)
over an in-memory transport (:class:`~roslibpy_lite.transports.memory.MemoryTransport`)
to the bridge's own session code, run in memory over a ROS graph held in memory
(:mod:`rosbridge_core.memory`). So the API and the client's validation are the
real client's, and every answer, refusal and error is the bridge's, by
construction. Code written against :class:`~roslibpy_lite.api.Ros` runs
unchanged on it::

    from roslibpy_lite.mock import MockRos

    async def test_my_node() -> None:
        ros = MockRos()
        ros.advertise_service("/mult", "mult_msgs/srv/MultFloats",
                              lambda req: {"result": req["x"] * req["y"]})
        await my_node(ros)                       # the code under test
        await ros.drain()                        # let async callbacks finish
        assert ros.published("/cmd") == [{"data": 6.0}]
        ros.inject("/sensor", {"data": 1.5})     # play the robot's side

What it checks, like a real bridge would:

- a topic has one type: advertising it here with another type raises
  :class:`~roslibpy_lite.exceptions.UsageError`; subscribing with another type
  is refused as the bridge refuses it: ``await ros.subscribe(...)`` raises
  :class:`~roslibpy_lite.exceptions.StatusError`, and without ``await`` the
  error hooks (:meth:`~roslibpy_lite.ros.RosBase.on_error`) get it;
- a published message must fit its type: typed messages are checked against
  their class, dicts against the generated class of the type when there is
  one (:class:`~roslibpy_lite.exceptions.InvalidMessageError` names the field);
- every message travels in its wire form (a JSON round trip), so subscribers
  never share objects with publishers;
- a service request that leaves fields out reaches the handler with their
  defaults filled in, as ROS gives it to a server behind a bridge.

Delivery is deterministic: ``publish`` hands the message to every
subscription of the topic before it returns (sync callbacks run at once,
in subscription order); async callbacks run in their subscription's task,
and ``await ros.drain()`` returns once they have taken everything.
Latched topics (``advertise(..., latch=True)``) give the first subscription
the last message. Service calls reach the handler through the same ops as on
a bridge; a handler that raises fails the call with
:class:`~roslibpy_lite.exceptions.ServiceError` carrying its text, an unknown
service fails the same way at once, a slow one raises
:class:`~roslibpy_lite.exceptions.RosTimeoutError`.
Actions likewise (:mod:`roslibpy_lite.actions`): a goal reaches the handler
served here by ``advertise_action``, and its feedback and result come back; a
goal to an action nobody serves, of an unknown type, or that does not fit the
type fails as on the bridge.

Connection trouble can be played too: :meth:`MockRos.disconnect` and
:meth:`MockRos.reconnect` move the state like a real drop does (calls in
flight fail with :class:`~roslibpy_lite.exceptions.Disconnected`, publishes
are buffered per publisher, ``offline_buffer`` deep, and delivered after the
reconnect has restored every handle).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from .exceptions import UsageError
from .messages import check_dict, message_type, to_wire
from .ros import RosBase
from .transports.memory import MemoryTransport

if TYPE_CHECKING:
    from msgs.runtime import Message

__all__ = ["MockRos"]


class MockRos(RosBase):
    """An in-memory :class:`~roslibpy_lite.api.Ros` (see the module docstring).

    Args:
        offline_buffer: messages kept per publisher while :meth:`disconnect`-ed
            (0: publishing then raises Disconnected), as on the real client.
        validate: check dict messages at the call against the generated class
            of their type when there is one (default on), as the real client
            does. The bridge's session checks them anyway, and reports a misfit
            later, through the error hooks.
        strict: refuse dicts that leave fields out, as the real client's ``strict``.
    """

    def __init__(self, *, offline_buffer: int = 100, validate: bool = True,
                 strict: bool = False) -> None:
        self._bridge = MemoryTransport()
        super().__init__(self._bridge, offline_buffer=offline_buffer, validate=validate,
                         strict=strict)
        self._bridge.open()

    def __repr__(self) -> str:
        topics = [name for name, _ in self._bridge.server.graph.topic_names_and_types()]
        return f"<MockRos {self.state.value} topics={topics}>"

    # -- connection trouble ----------------------------------------------------------------------

    def disconnect(self) -> None:
        """Play a dropped connection: state ``RECONNECTING``; calls in flight fail."""
        self._host.check_open()
        self._bridge.drop()

    def reconnect(self) -> None:
        """Play a reconnect: handles are restored, buffered publishes delivered, ``CONNECTED``."""
        self._host.check_open()
        self._bridge.open()

    # -- test conveniences ---------------------------------------------------------------------

    def published(self, topic: str) -> list[dict[str, Any]]:
        """Every message published on ``topic`` through this mock, oldest first (wire form)."""
        return [dict(m) for m in self._bridge.history.get(topic, [])]

    def inject(
        self,
        topic: str,
        msg: Mapping[str, Any] | Message,
        type: str | type[Message] | None = None,
        *,
        latch: bool = False,
    ) -> None:
        """Deliver ``msg`` to the subscribers of ``topic`` as if the robot published it.

        ``type`` defaults to the topic's known type (or the message's class).
        Not recorded in :meth:`published`. ``latch`` keeps it for late subscribers.
        """
        self._host.check_open()
        if type is None:
            known = self._bridge.topic_type(topic)
            if known is not None:
                type = known
            elif hasattr(msg, "_type"):
                type = msg._type
            else:
                raise UsageError(f"inject {topic}: the topic has no type yet; pass type=")
        type_name, cls = message_type(type)
        what = f"inject to {topic}"
        wire = to_wire(msg, type_name, cls, what)
        if wire is msg:
            check_dict(wire, self._topics.check_class(type_name, cls), what)
        self._bridge.inject(topic, type_name, wire, latch=latch)

    def add_node(self, name: str, parameters: Mapping[str, Any] | None = None) -> None:
        """Play another ROS node, ``name`` (``/ns/name``): listed in the graph, and serving
        ``parameters`` (get, set, list) as an rclpy node does."""
        self._host.check_open()
        self._bridge.add_node(name, parameters)

    def subscribers(self, topic: str) -> int:
        """How many open subscriptions ``topic`` has."""
        return len(self._topics.by_topic.get(topic, ()))

    def served(self) -> list[str]:
        """The names of the services served through this mock."""
        return sorted(self._services.servers)

    def served_actions(self) -> list[str]:
        """The names of the actions served through this mock."""
        return sorted(self._actions.servers)

    async def drain(self) -> None:
        """Return once every async callback has taken every message delivered so far."""
        while True:
            busy = [s for s in self._topics.subscriptions.values()
                    if s._async_cbs and (s._queue or not s._idle.is_set())]
            if not busy:
                return
            for sub in busy:
                await sub._drained()
