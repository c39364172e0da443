"""The relay's side: a :class:`~rosbridge_core.graph.Graph` of one robot, read from Zenoh.

A relay holds one :class:`ZenohGraph` per robot its clients ask for, shared by their
sessions, over one Zenoh session. What the sessions ask of ROS becomes the keys of
:mod:`bridge_server.zenoh.keys`:

- a topic's shared subscription is a Zenoh advanced subscriber with recovery (what a
  robot's reliable topic published while its link was down comes from its window once
  the link is back, in order; what the window no longer held is counted and told to the
  robot's clients: :mod:`bridge_server.zenoh.replay`) plus a demand token (so the robot
  subscribes in ROS), and each message is built from the CDR bytes the robot put: JSON
  straight from CDR (:mod:`rosbridge_core.codec.cdr_json`), CBOR from ``msgs.cdr``'s
  decoding, ``cbor-raw`` the bytes as they came, each at most once per message;
- a shared publisher is a publisher token (the robot makes the ROS publisher) and one put
  of CDR bytes (``msgs.cdr``) per message;
- a service call is one query answered by the robot's own ``call_service``;
- a goal is one query whose replies stream its acceptance, feedback and result from the
  robot's own action client, with a liveliness token of the goal's that takes it (canceled)
  with the relay if the relay dies; a cancel is a query;
- a service a client serves is a queryable the robot's ROS service forwards each call to,
  and a token that keeps that ROS service up (a token the robot refuses, another relay's
  client serving the name, is reported to the session); an action a client serves
  likewise, each ROS goal one query whose replies stream the goal's feedback and end;
- node parameters are queries run by the robot's own parameter methods;
- the graph, the types' definitions and typedefs come from the robot's snapshot (kept
  up to date by its puts), so the sessions' synchronous questions read a cache.

Types are ``msgs`` classes: generated ones, or built at run time from the definitions the
robot sent (:mod:`msgs.dynamic`), so a robot's own types need nothing installed on the
relay. Each robot's are its own (:attr:`ZenohGraph.wire_types`, a
:class:`~msgs.dynamic.TypeStore`): two robots may define one name differently and each
robot's samples are decoded, and the publishes to it encoded, in its own layout. A
definition is built once per text (not per sample), within :class:`TypeLimits`; a robot's
types are released when it has left and none of this relay's clients uses them.

The package, a module a job: :mod:`.zenoh_graph` (:class:`ZenohGraph`: the robot's life,
types and what its sessions hold), :mod:`.topics` (feeds, messages, publishers),
:mod:`.services` and :mod:`.actions` (what clients call and serve), :mod:`.queries` (service
calls and parameters, each a query), :mod:`.introspection` (the snapshot's answers),
:mod:`.converter` (:class:`RelayConverter`) and :mod:`.robot` (the :class:`~.robot.Robot`
protocol the parts use of their graph, so none imports it back).
"""

from __future__ import annotations

from bridge_server.zenoh.graph.actions import (
    ZenohActionClient,
    ZenohSentGoal,
    ZenohServedAction,
    ZenohServedGoal,
)
from bridge_server.zenoh.graph.converter import RelayConverter
from bridge_server.zenoh.graph.services import ZenohRosCall, ZenohServedService
from bridge_server.zenoh.graph.topics import ZenohFeed, ZenohMessage, ZenohPublisher
from bridge_server.zenoh.graph.zenoh_graph import ZenohGraph
from bridge_server.zenoh.typestore import (
    MAX_DEFINITION_BYTES,
    MAX_TYPES_PER_ROBOT,
    TypeLimits,
    TypeRefused,
)

__all__ = ["MAX_DEFINITION_BYTES", "MAX_TYPES_PER_ROBOT", "RelayConverter", "TypeLimits",
           "TypeRefused", "ZenohActionClient", "ZenohFeed", "ZenohGraph", "ZenohMessage",
           "ZenohPublisher", "ZenohRosCall", "ZenohSentGoal", "ZenohServedAction",
           "ZenohServedGoal", "ZenohServedService"]
