"""The wire contract between a robot's exporter and the relays: Zenoh keys and payloads.

Every key of a robot is under ``<robot>/``. A ROS name maps to key chunks by dropping
its leading ``/`` (``/camera/image`` of robot ``r1`` is ``r1/camera/image``), as
zenoh-bridge-ros2dds maps names under its ``namespace``. What is not topic data lives
under chunks that start with ``@``: Zenoh's verbatim chunks, which no wildcard matches
and no ROS name can spell, so ``r1/**`` is all of ``r1``'s topics and nothing else.

=======================================  ==============================================
key                                      what
=======================================  ==============================================
``<robot>/<topic>``                      one put per ROS message: its CDR bytes as they
                                         came; attachment :class:`Meta` (JSON), naming
                                         the session that put it (a relay takes only
                                         the name's holder's)
``<robot>/@claim/<zid>``                 liveliness token of a robot announcing its name
                                         (``zid``: its Zenoh session's id), before anything
                                         else; one robot per name: a robot that finds
                                         another's withdraws it and waits (:class:`Claims`)
``<robot>/@alive/<zid>``                 liveliness token of the robot holding the name,
                                         once it serves: the robot is there
``<robot>/@demand/<relay>/<topic>``      liveliness token of a relay watching ``topic``:
                                         the robot subscribes while one exists
``<robot>/@latched/<topic>``             queryable: the last message of a latched topic
``<robot>/@graph``                       :class:`Snapshot` JSON: put on change, and a
                                         queryable answering the current one; attachment
                                         the Zenoh id of the session (as ``Meta.zid``)
``<robot>/@call/<relay>/<service>``      queryable: a service call of relay ``relay``,
                                         :class:`CallRequest` JSON in, the response dict
                                         (JSON) or an error
``<robot>/@advertise/<relay>/<latch>/``  liveliness token of a relay's publisher
``<pkg>/msg/<Name>/<topic>``             (``latch`` is ``latched`` or ``volatile``)
``<robot>/@in/<topic>``                  a client's message to publish: CDR bytes,
                                         attachment :class:`Meta` (type and latch); the
                                         only key a relay puts under
``<robot>/@goal/<relay>/<action>``       queryable: a goal of relay ``relay``,
                                         :class:`GoalRequest` JSON in; the replies
                                         stream :class:`GoalEvent` JSON (accepted,
                                         feedback, ..., the result last)
``<robot>/@running/<relay>/<goal>``      liveliness token of a goal a relay sent: the
                                         robot cancels the goal when it goes
``<robot>/@cancel/<relay>/<goal>``       queryable: cancel that goal (the answer comes
                                         as a ``cancel`` event of the goal's query)
``<robot>/@serve/<relay>/<pkg>/srv/``    liveliness token of a service a relay's client
``<Name>/<service>``                     serves: the robot serves it in ROS meanwhile
                                         (``<pkg>/action/<Name>/<action>``: an action)
``<robot>/@refused/<relay>/<kind>/``     the robot's put to a relay whose ``@serve``
``<name>``                               token it does not take (another relay's client
                                         serves the name, or the robot cannot serve it):
                                         why, as text (``kind``: ``srv`` or ``action``);
                                         put again while the token lives
``<robot>/@serving/<relay>/<service>``   the relay's queryable: a ROS call's request
                                         JSON in, the response JSON (or an error) out
``<robot>/@executing/<relay>/<action>``  the relay's queryable: a ROS goal of an action a
                                         client serves, :class:`Execute` JSON in; the
                                         replies stream :class:`GoalEvent` JSON (feedback,
                                         the result last); a cancel is :class:`Execute`
                                         with ``cancel`` set
``<robot>/@param/<node>``                queryable: a node's parameters,
                                         :class:`ParamRequest` JSON in, the answer JSON
``<robot>/<topic>/@adv/...``             ``zenoh.ext``'s own keys of a reliable topic's
                                         advanced publisher (its cache's queryable, its
                                         liveliness token and heartbeat: :mod:`.replay`)
=======================================  ==============================================

``docs/guides/relay.md`` describes the contract for people; where it differs from
zenoh-bridge-ros2dds it says why. This module is the key table; the payloads' dataclasses
and codecs are :mod:`.payloads`'s and the chunk checks :mod:`.chunks`'s, named here again.
"""

from __future__ import annotations

import contextlib

from bridge_server.zenoh.chunks import check_relay, check_robot
from bridge_server.zenoh.payloads import (
    CallRequest,
    Execute,
    GoalEvent,
    GoalRequest,
    Meta,
    ParamRequest,
    Snapshot,
)
from rosbridge_core.interfaces import BridgeError, Kind, canonical_name
from rosbridge_core.security.names import check_name

__all__ = [
    "ADV",
    "ADVERTISE",
    "ALIVE",
    "CALL",
    "CANCEL",
    "CLAIM",
    "CONTROL",
    "DEMAND",
    "EXECUTING",
    "GOAL",
    "GOAL_WAIT",
    "GRAPH",
    "IN",
    "LATCHED",
    "PARAM",
    "PLACE",
    "PRESENCE",
    "REFUSED",
    "RELAY_ANSWERS",
    "RELAY_ASKS",
    "RELAY_PUTS",
    "RELAY_SCOPED",
    "RELAY_TOKENS",
    "ROBOT_ANSWERS",
    "RUNNING",
    "SERVE",
    "SERVING",
    "CallRequest",
    "Claims",
    "Execute",
    "GoalEvent",
    "GoalRequest",
    "Meta",
    "ParamRequest",
    "Snapshot",
    "advertise_key",
    "alive_key",
    "check_relay",
    "check_robot",
    "claim_key",
    "key_of",
    "name_of",
    "parse_advertise",
    "parse_alive",
    "parse_demand",
    "parse_scoped",
    "parse_serve",
    "refused_key",
    "serve_key",
]

ALIVE = "@alive"
CLAIM = "@claim"
DEMAND = "@demand"
LATCHED = "@latched"
PLACE = "place"
"""The ``@latched`` query's parameter (``<robot>/@latched/<topic>?place``) of a relay that
starts watching a topic: the robot answers a replayed topic (one with a window) with an
empty reply whose attachment (:class:`Meta`) numbers the last message it put, and the
relay's viewers take nothing up to there. Without it the robot's window would reach them:
a relay's new advanced subscriber that hears the topic's heartbeat before a message asks
the robot for everything the window holds."""
GRAPH = "@graph"
CALL = "@call"
ADVERTISE = "@advertise"
IN = "@in"
GOAL = "@goal"
RUNNING = "@running"
CANCEL = "@cancel"
SERVE = "@serve"
SERVING = "@serving"
EXECUTING = "@executing"
PARAM = "@param"
REFUSED = "@refused"
ADV = "@adv"
"""``zenoh.ext``'s chunk after a topic's key: its advanced publisher's cache, token and
heartbeat (not a control chunk of ours: it comes after the topic, not the robot)."""

GOAL_WAIT = 30 * 24 * 3600.0
"""Seconds a goal's query (``@goal``, ``@executing``) stays open: a goal may run as long as
it likes (a session's ``goal_timeout`` ends it sooner if set)."""

CONTROL = (ALIVE, CLAIM, DEMAND, LATCHED, GRAPH, CALL, ADVERTISE, IN, GOAL, RUNNING, CANCEL, SERVE,
           SERVING, PARAM, EXECUTING, REFUSED)
"""Every control chunk (Zenoh's verbatim chunks, which no wildcard matches: access rules
name each)."""

PRESENCE = (ALIVE, CLAIM)
"""The chunks of a robot's own presence tokens: a robot declares them, relays follow them (a
router's access rules let no relay announce a robot, nor block its name)."""

RELAY_TOKENS = (DEMAND, ADVERTISE, RUNNING, SERVE)
"""The chunks of a relay's liveliness tokens (``<robot>/<chunk>/<relay>/...``)."""
RELAY_ASKS = (CALL, GOAL, CANCEL)
"""The chunks of a relay's queries that name it (``<robot>/<chunk>/<relay>/...``)."""
RELAY_ANSWERS = (SERVING, EXECUTING)
"""The chunks of a relay's queryables and their replies (``<robot>/<chunk>/<relay>/...``)."""
ROBOT_ANSWERS = (GRAPH, LATCHED, PARAM)
"""The chunks of a robot's queryables that any relay may ask and that name no relay."""
RELAY_PUTS = (IN,)
"""The only chunks a relay puts under: a client's message for the robot to publish (no
relay puts topic data, a graph document or anything else under a robot's keys)."""

RELAY_SCOPED = (*RELAY_TOKENS, *RELAY_ASKS, *RELAY_ANSWERS, REFUSED)
"""The control chunks whose next chunk names a relay (``<robot>/<chunk>/<relay>/...``): a
router's access rules hold each relay to its own (its certificate's common name), so what
the robot takes as a relay's id there is that relay's."""


def key_of(robot: str, name: str, where: str = "") -> str:
    """The key of ROS name ``name`` (``/a/b``) of ``robot``, under ``where`` (``@in``, ...)
    if given; ``InvalidNameError`` for a name ROS would refuse."""
    check_name(name)
    return f"{robot}/{where}/{name[1:]}" if where else f"{robot}/{name[1:]}"


def name_of(key: str, skip: int) -> str:
    """The ROS name in ``key`` after its first ``skip`` chunks (``r1/@in/a/b``, 2: ``/a/b``)."""
    return "/" + key.split("/", skip)[skip]


def alive_key(robot: str, zid: str) -> str:
    """The liveliness token of robot ``robot`` announced by the Zenoh session ``zid``."""
    return f"{robot}/{ALIVE}/{zid}"


def claim_key(robot: str, zid: str) -> str:
    """The token of the Zenoh session ``zid`` announcing robot name ``robot``."""
    return f"{robot}/{CLAIM}/{zid}"


def parse_alive(key: str) -> tuple[str, str]:
    """(robot, Zenoh id) of a robot's ``@alive`` or ``@claim`` token (the id ``""`` for a
    bare ``<robot>/@alive``, a robot that names no session)."""
    robot, _, rest = key.partition("/")
    return robot, rest.partition("/")[2]


class Claims:
    """The sessions announcing one robot name (their ``@alive`` tokens), in the order their
    tokens came: the first holds the name, the others are refused while it does."""

    def __init__(self) -> None:
        self.order: list[str] = []

    @property
    def holder(self) -> str | None:
        """The Zenoh id holding the name (``None``: no robot announces it)."""
        return self.order[0] if self.order else None

    def seen(self, zid: str, here: bool) -> bool:
        """A token of ``zid`` came (``here``) or went; whether it is one refused now (it
        came while another holds the name)."""
        if not here:
            with contextlib.suppress(ValueError):
                self.order.remove(zid)
            return False
        if zid not in self.order:
            self.order.append(zid)
        return self.order[0] != zid


def parse_scoped(key: str) -> tuple[str, str]:
    """(relay id, ROS name) of a key that names a relay (``<robot>/<chunk>/<relay>/<name>``,
    :data:`RELAY_SCOPED`); ``BridgeError`` naming the key if it does not."""
    parts = key.split("/", 3)
    if len(parts) < 4:
        raise BridgeError(f"key {key!r} names no relay and name")
    return check_relay(parts[2]), "/" + parts[3]


def parse_demand(key: str) -> tuple[str, str]:
    """(relay id, topic) of a demand token's key."""
    relay = key.split("/", 3)[2]
    return relay, name_of(key, 3)


def advertise_key(robot: str, relay: str, topic: str, type_name: str, latch: bool) -> str:
    """The key of a relay's publisher token (see the module's table)."""
    pkg, kind, name = canonical_name(type_name, "msg").split("/")
    where = f"{ADVERTISE}/{relay}/{'latched' if latch else 'volatile'}/{pkg}/{kind}/{name}"
    return key_of(robot, topic, where)


def parse_advertise(key: str) -> tuple[str, str, bool, str]:
    """(relay id, topic, latch, type) of a publisher token's key."""
    parts = key.split("/", 7)
    return parts[2], "/" + parts[7], parts[3] == "latched", "/".join(parts[4:7])


def serve_key(robot: str, relay: str, name: str, type_name: str, kind: Kind = "srv") -> str:
    """The key of a relay's served-service (``kind`` ``action``: served-action) token (see
    the module's table)."""
    pkg, _, short = canonical_name(type_name, kind).split("/")
    return key_of(robot, name, f"{SERVE}/{relay}/{pkg}/{kind}/{short}")


def refused_key(robot: str, relay: str, name: str, kind: Kind = "srv") -> str:
    """The key of the robot's refusal of ``relay``'s served-service (``kind`` ``action``:
    served-action) token of ``name`` (see the module's table)."""
    return key_of(robot, name, f"{REFUSED}/{relay}/{kind}")


def parse_serve(key: str) -> tuple[str, str, str]:
    """(relay id, service or action, type: ``pkg/srv/Name`` or ``pkg/action/Name``) of a
    served token's key."""
    parts = key.split("/", 6)
    return parts[2], "/" + parts[6], "/".join(parts[3:6])
