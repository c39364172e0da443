"""The robot's side of the relay tier: its bridge's :class:`~rosbridge_core.graph.Graph` on Zenoh.

``roslibpy-lite-bridge --zenoh-connect tcp/router:7447 --robot r1`` runs one
:class:`Exporter` beside (or, with ``--no-websocket``, instead of) the websocket listener.
It dials out to the routers and offers the robot under ``r1/`` as :mod:`.keys` describes:

- a topic is subscribed in ROS only while some relay's demand token for it exists (an
  unwatched robot sends nothing); each message is put once, as the CDR bytes that came,
  however many relays and viewers watch it; a reliable topic's through an advanced
  publisher that keeps a bounded window of its last messages for relays whose link
  dropped (:mod:`.replay`: nothing lost in an outage within the window);
- a relay's publisher token makes a shared publisher of the Graph, and the messages put
  under ``@in/`` are published through it, CDR bytes as they came;
- service calls are queries, answered by the Graph's own ``call_service``;
- a goal is a query whose replies stream what the Graph's own action client reports
  (accepted, feedback, the result); a cancel is a query; a goal whose relay's ``@running``
  token goes (the relay died) is canceled, as the bridge cancels a leaving client's goals;
- a service a relay's client serves is served in ROS by the Graph's ``serve`` while its
  ``@serve`` token lives; each ROS call is a query to the relay, the reply answers it; the
  first relay's token keeps a name, and a later one (another relay's client) is refused
  with a put under ``@refused`` that its relay passes to the client (put again while the
  token lives: a put can reach a relay before the network routes it there);
- so is an action a relay's client serves (``serve_action``): each ROS goal is a query to
  the relay whose replies stream the goal's feedback and its end; a ROS cancel is a query;
- node parameters are queries run by the Graph's parameter methods;
- the graph (topics, services, nodes and the definitions of their types) is put when it
  changes, and answers queries.

What a relay may ask is the robot's decision: every request above is held to the robot's
relay policy, a role in the auth file's format (``--relay-role``; :data:`DEFAULT_POLICY`
without one: everything but taking over a name a ROS node serves). A refused call, goal,
parameter or served name is answered with the reason; a refused topic is logged and left
unwatched or unpublished. A relay with a valid certificate, compromised or misconfigured,
can do no more than the policy lets it.

It talks to ROS only through the Graph protocol, so it knows nothing of rclpy. Zenoh calls
back on its own threads: every callback crosses to the event loop with
``call_soon_threadsafe`` and the Graph is used there only.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import logging
import math
import random
import secrets
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import zenoh

from bridge_server.zenoh import keys
from bridge_server.zenoh.bulk import BulkSender
from bridge_server.zenoh.keys import (
    GOAL_WAIT,
    CallRequest,
    Execute,
    GoalEvent,
    GoalRequest,
    Meta,
    ParamRequest,
    Snapshot,
)
from bridge_server.zenoh.link import ZenohOptions, answering, ignore_replies, open_session, tokens
from bridge_server.zenoh.priority import Priorities, TopicPriority
from bridge_server.zenoh.replay import (
    DEMAND_LINGER,
    ReplayBudget,
    ReplayPublisher,
    ReplayWindow,
    window_metrics,
)
from bridge_server.zenoh.robot_graph import GraphSnapshots
from bridge_server.zenoh.uplink import Uplink, uplink_use
from rosbridge_core.graph import (
    ActionClient,
    Graph,
    Message,
    Publisher,
    RosCall,
    SentGoal,
    ServedAction,
    ServedGoal,
    ServedService,
    Status,
    TopicFeed,
)
from rosbridge_core.interfaces import BridgeError, ConversionError, Kind, args_mapping
from rosbridge_core.security.permissions import Role
from rosbridge_core.session.actions import ACTION_LINGER, CLIENT_IDLE

if TYPE_CHECKING:
    from prometheus_client.core import Metric

__all__ = ["Exporter"]

log = logging.getLogger("bridge_server.zenoh.exporter")

SNAPSHOT_INTERVAL = 1.0
"""Seconds between two looks at the ROS graph (a changed one is put at once)."""

UNHELD_PUBLISHER_WAIT = 10.0
"""Seconds a publisher made for a message under ``@in/`` that no relay's ``@advertise``
token holds is kept: the token may come after the first message (Zenoh carries
declarations and data apart), or never (the message came after the token went, or from a
relay that holds none); then the publisher goes."""

SERVED_CALL_WAIT = 60.0
"""Seconds a ROS call of a relay-served service waits for the relay's reply (the relay's
session gives up sooner, after its ``served_call_timeout``; then the caller is not answered,
as on the bridge)."""


@dataclass
class _Export:
    """One watched topic: the Graph's feed, the relays that watch it, the last message put."""

    feed: TopicFeed
    listener: Callable[[Message], None]
    relays: set[str] = field(default_factory=set)
    seq: int = 0
    epoch: str = field(default_factory=lambda: secrets.token_hex(6))
    """This stream of the topic: a topic watched anew starts again at seq 1, in a new epoch."""
    last: tuple[Message, bytes] | None = None
    replay: ReplayPublisher | None = None
    """The topic's advanced publisher with its window (made at its first reliable message)."""
    lingering: bool = False
    """No relay watches it, and it stays a while (:data:`~.replay.DEMAND_LINGER`)."""


class _RobotGoal:
    """A relay's goal on the robot: what the Graph's action client reports goes back as
    replies to the goal's query (the :class:`~rosbridge_core.graph.GoalListener`)."""

    def __init__(self, exporter: Exporter, query: zenoh.Query, key: tuple[str, str],
                 action: str, client: ActionClient) -> None:
        self.exporter = exporter
        self.query = query
        self.key = key
        """(the id of the relay that sent it, the goal's id there)"""
        self.action = action
        self.client = client
        self.sent: SentGoal | None = None

    def _reply(self, event: GoalEvent, last: bool = False) -> None:
        with contextlib.suppress(zenoh.ZError):
            self.query.reply(self.query.key_expr, event.encode())
        if last:
            self.exporter.goals.pop(self.key, None)
            self.query.drop()  # type: ignore[no-untyped-call]

    def on_accepted(self) -> None:
        """Accepted: the relay learns the goal's id in ROS."""
        handle = self.sent.handle if self.sent is not None else None
        uuid = bytes(handle.goal_id.uuid).hex() if handle is not None else ""
        self._reply(GoalEvent("accepted", uuid=uuid))

    def on_rejected(self) -> None:
        """Rejected: the last reply."""
        self._reply(GoalEvent("rejected"), last=True)

    def on_feedback(self, feedback: Any) -> None:
        """One feedback message, as rosbridge JSON."""
        self._reply(GoalEvent("feedback", values=self.client.feedback_conv.to_obj(feedback)))

    def on_cancel_answer(self, code: int) -> None:
        """The server's answer to a cancel request."""
        self._reply(GoalEvent("cancel", code=code))

    def on_result(self, status: int, result: Any) -> None:
        """The end: status and result (None: the goal never ran)."""
        values = self.client.result_conv.to_obj(result) if result is not None else None
        self._reply(GoalEvent("result", status=int(status), values=values), last=True)

    def on_failed(self, why: str) -> None:
        """Not called by the robot's Graph (its goals fail through ``on_result``)."""
        self._reply(GoalEvent("failed", text=why), last=True)


_GOAL_SERVICE = "/_action/send_goal"
_CANCEL_SERVICE = "/_action/cancel_goal"
CLAIM_WAIT = 1.0
"""Seconds the robot waits for the tokens of its name when it announces itself (and at
most between one holding it leaving and trying again)."""

RETURN_POLL = 0.25
"""Seconds between two looks at the claims of its name by a robot back from an outage,
for a lease after its link is back (the network tells it of them as a rule, but not
always at once: a look at once may find none, and the claim's token may not come)."""

CLAIM_RECHECK = 5.0
"""Seconds between two looks, by a robot refused its name, at whether the holder left (it
is told at once as a rule)."""

REFUSAL_REPEAT = (0.25, 4.0)
"""Seconds before a refusal under ``@refused`` is put again while the refused token lives,
first and at most (doubling): a put that came before the network routed it to the relay's
subscriber reached nobody, and the relay would believe its client serves the name."""

DIAL_WARNING = 4.0
"""Seconds the robot dials without any router answering before it says so (and again
after each as many)."""

DEFAULT_POLICY = Role.from_table("relays (default)", {"all": ["*"], "deny": {"take_over": ["*"]}})
"""What relays may ask of a robot that names no ``--relay-role``: every topic, service,
action and parameter, but not serving a name that a ROS node of the robot already serves
(two servers of one name would answer its callers by chance)."""


@dataclass
class _Served:
    """A service or action a relay's client serves, in ROS on the robot."""

    relay: str
    type_name: str
    ros: ServedService | ServedAction
    goals: dict[int, ServedGoal] = field(default_factory=dict)
    """An action's ROS goals in flight, by ``id()``."""


class Exporter:
    """The robot ``robot``'s Graph offered on Zenoh (see the module's text)."""

    def __init__(self, graph: Graph, robot: str, options: ZenohOptions,
                 graph_changed: Callable[[], None] = lambda: None,
                 snapshot_interval: float = SNAPSHOT_INTERVAL,
                 policy: Callable[[], Role | None] = lambda: DEFAULT_POLICY,
                 replay: ReplayWindow | None = None,
                 priorities: dict[str, TopicPriority] | None = None) -> None:
        self.graph = graph
        self.priorities = Priorities(priorities)
        """Each topic's Zenoh priority on the robot's link (``--relay-priority`` overrides)."""
        self.uplink = Uplink(robot, options)
        self.bulk: BulkSender | None = None
        """Puts the big messages (:mod:`.bulk`), once the session is open."""
        """Whether a router holds the robot's presence, and what it sends (:mod:`.uplink`)."""
        self.replay = replay or ReplayWindow()
        """How much of each reliable topic is kept for relays whose link dropped."""
        self.replay_budget = ReplayBudget(self.replay.total)
        self.demand_linger = DEMAND_LINGER
        self.policy = policy
        """The role relays are held to, looked up at each request (an auth file read again on
        SIGHUP changes it at once); ``None``: the role is gone, and every request is refused."""
        self.policy_refused: dict[tuple[str, str], int] = {}
        """Requests refused by the policy, by (capability, name): logged the first time."""
        self.robot = keys.check_robot(robot)
        self.options = options
        self.graph_changed = graph_changed
        self.snapshot_interval = snapshot_interval
        self.epoch = secrets.token_hex(6)
        self.session: zenoh.Session | None = None
        self.exports: dict[str, _Export] = {}
        self.publishers: dict[tuple[str, str, bool], tuple[Publisher, set[str]]] = {}
        self.unheld_wait = UNHELD_PUBLISHER_WAIT
        self._unheld: set[tuple[str, str, bool]] = set()
        self.action_clients: dict[tuple[str, Any], ActionClient] = {}
        """The robot's action clients of relays' goals by (action, type); one no goal used
        for ``client_idle`` seconds is destroyed, as the bridge's are."""
        self.client_idle = CLIENT_IDLE
        self.sweeps = 0
        """How many times idle action clients were looked for."""
        self._client_used: dict[tuple[str, Any], float] = {}
        self._sweeper: asyncio.TimerHandle | None = None
        self.goals: dict[tuple[str, str], _RobotGoal] = {}
        """Relays' goals in flight by (relay id, goal id)."""
        self._early_cancels: set[tuple[str, str]] = set()
        self._waiting: set[tuple[str, str]] = set()
        """Relays' goals waiting for a ready action server (not sent yet)."""
        self.served: dict[str, _Served] = {}
        """Services relays' clients serve by name; actions by their goal service's name."""
        self._served_goals: dict[int, str] = {}  # id(ServedGoal) -> its id in its query
        self.refusing: dict[str, asyncio.TimerHandle] = {}
        """The next put of each refusal whose token lives, by the refusal's key."""
        self._lingering: dict[str, ServedAction] = {}
        self._served_goal_ids = itertools.count()
        self.snapshot = Snapshot()
        self._snapshot_bytes = b""
        self.graph_snapshots = GraphSnapshots(graph)
        self._entities: list[Any] = []
        self._tasks: set[asyncio.Task[None]] = set()
        self._loop = asyncio.get_running_loop()
        self._runner: asyncio.Task[None] | None = None
        self.uplinks: set[str] = set()
        """The Zenoh ids of the routers this robot has a transport to now."""
        self.uplink_lost = 0
        """How many times the robot lost its last router."""
        self._uplink_since = 0.0  # loop time the uplink came (back)
        self.zid = ""
        """This robot's Zenoh session id (once the session is open)."""
        self.holding = False
        """Whether this robot holds its name on Zenoh (and serves there)."""
        self.refused_by: set[str] = set()
        """The Zenoh ids of the robots holding this robot's name while it waits for it."""
        self.name_refusals = 0
        """Robots refused this robot's name while it held it."""
        self._claim_changed = asyncio.Event()
        self._listeners: list[Any] = []  # the uplink's and the name's, while the session is
        self._away_until = 0.0
        """Loop time until which another robot's claim that comes is one made while this
        robot was away (its last uplink lost since it took its name: ``inf`` until the
        uplink is back, then a lease more, the time the network takes to tell it the claims
        it missed)."""
        self._returned = asyncio.Event()
        """Set when the robot, back from an outage, may have met another robot's claim."""

    # -- life ----------------------------------------------------------------------------------

    def start(self) -> None:
        """Dial out (in the background: the robot serves ROS while no router answers)."""
        self._runner = self._loop.create_task(self._run(), name="zenoh-exporter")
        self._runner.add_done_callback(_report)

    async def _run(self) -> None:
        opening = asyncio.ensure_future(open_session(self.options))
        waited, wait = 0.0, DIAL_WARNING
        try:
            while not (await asyncio.wait({opening}, timeout=wait))[0]:
                waited += wait
                wait = min(wait * 2, 300.0)  # said again, ever less often
                self.uplink.dialing(waited)
        except asyncio.CancelledError:
            opening.cancel()
            raise
        self.session = opening.result()
        self.bulk = BulkSender(self.session)
        await self._joined(self.session)

    async def _joined(self, session: zenoh.Session) -> None:
        """Hold the robot's name on the open ``session`` (:meth:`_claim`), offer the robot
        and keep its graph snapshot fresh while it holds the name; withdraw when it finds,
        back from an outage, that another robot took the name meanwhile, and wait for it
        again."""
        here = self._on_loop
        self.zid = str(session.zid())
        self.uplink.watch(session, self.zid)
        self._listeners = [
            session.info.declare_transport_events_listener(here(self._on_transport),
                                                           history=True),
            session.liveliness().declare_subscriber(f"{self.robot}/{keys.CLAIM}/*",
                                                    here(self._on_claim)),
        ]
        claim = None
        while True:
            claim = await self._claim(session, claim)
            self._entities = [claim]
            self._serve(session)
            claim = await self._hold(session)
            self._withdraw(keep=claim)

    def _serve(self, session: zenoh.Session) -> None:
        """Offer the robot on ``session`` (its name held)."""
        r = self.robot
        here = self._on_loop
        live = session.liveliness()
        self.holding = True
        self._away_until = 0.0
        self.snapshot = self._take_snapshot()
        self._snapshot_bytes = self.snapshot.encode()
        self._entities += [
            session.declare_queryable(f"{r}/{keys.GRAPH}", here(self._answer_graph)),
            session.declare_queryable(f"{r}/{keys.LATCHED}/**", here(self._answer_latched)),
            session.declare_queryable(f"{r}/{keys.CALL}/**", here(self._answer_call)),
            session.declare_queryable(f"{r}/{keys.GOAL}/**", here(self._answer_goal)),
            session.declare_queryable(f"{r}/{keys.CANCEL}/**", here(self._answer_cancel)),
            session.declare_queryable(f"{r}/{keys.PARAM}/**", here(self._answer_param)),
            live.declare_subscriber(f"{r}/{keys.RUNNING}/**", here(self._on_running)),
            live.declare_subscriber(f"{r}/{keys.SERVE}/**", here(self._on_serve), history=True),
            session.declare_subscriber(f"{r}/{keys.IN}/**", here(self._on_in)),
            live.declare_subscriber(f"{r}/{keys.DEMAND}/**", here(self._on_demand), history=True),
            live.declare_subscriber(f"{r}/{keys.ADVERTISE}/**", here(self._on_advertise),
                                    history=True),
            live.declare_token(keys.alive_key(r, self.zid)),  # last: all above answers
        ]
        self.uplink.serving()  # said to be on Zenoh once a router holds its presence

    async def _hold(self, session: zenoh.Session) -> Any:
        """Keep the graph snapshot fresh while the robot holds its name; return its claim
        token when, back from an outage (its last uplink gone, then one back), it finds
        another robot's claim: that robot took the name meanwhile, and the held claim wins."""
        while True:
            back = self._loop.time() < self._away_until < math.inf
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(RETURN_POLL if back else self.snapshot_interval):
                    await self._returned.wait()
            if self._returned.is_set() or back:
                self._returned.clear()
                found = await tokens(session, f"{self.robot}/{keys.CLAIM}/*", CLAIM_WAIT)
                if {keys.parse_alive(key)[1] for key in found} - {self.zid}:
                    return self._entities[0]
            self._refresh_snapshot()

    def _withdraw(self, keep: Any = None) -> None:
        """Stop serving on Zenoh: release what the relays held and undeclare what the robot
        declared (but ``keep``)."""
        self.holding = False
        for task in list(self._tasks):
            task.cancel()
        for export in self.exports.values():
            self._unexport(export)
        self.exports.clear()
        for pub, _relays in self.publishers.values():
            self.graph.release_publisher(pub)
        self.publishers.clear()
        for goal in list(self.goals.values()):
            if goal.sent is not None:
                goal.sent.cancel()
        self.goals.clear()
        if self._sweeper is not None:
            self._sweeper.cancel()
            self._sweeper = None
        for client in self.action_clients.values():
            client.destroy()
        self.action_clients.clear()
        self._client_used.clear()
        for served in self.served.values():
            served.ros.destroy()
        self.served.clear()
        for timer in self.refusing.values():
            timer.cancel()
        self.refusing.clear()
        for action in self._lingering.values():
            action.destroy()
        self._lingering.clear()
        for entity in self._entities:
            if entity is not keep:
                with contextlib.suppress(zenoh.ZError):
                    entity.undeclare()
        self._entities.clear()

    async def _claim(self, session: zenoh.Session, token: Any = None) -> Any:
        """Announce the robot's name (its ``@claim`` token; ``token``: one declared already)
        and hold it: the token of another robot there already means that robot holds the
        name, and this one withdraws its token, says why (an error, with both Zenoh ids)
        and, serving nothing on Zenoh, waits for that robot to leave (a robot restarted
        before its old session's lease ended waits for that lease). The token held,
        returned."""
        live = session.liveliness()
        told: set[str] = set()
        while True:
            self._claim_changed.clear()
            if token is None:
                token = live.declare_token(keys.claim_key(self.robot, self.zid))
            found = await tokens(session, f"{self.robot}/{keys.CLAIM}/*", CLAIM_WAIT)
            others = {keys.parse_alive(key)[1] for key in found} - {self.zid}
            if not others:
                if told:
                    log.info("robot %s: the robot that held its name left; this robot "
                             "(Zenoh id %s) takes it", self.robot, self.zid)
                self.refused_by = set()
                return token
            token.undeclare()
            token = None
            self.refused_by = others
            if others - told:
                told |= others
                log.error("robot %s: another robot holds this name on the Zenoh network "
                          "(Zenoh id %s): this robot (Zenoh id %s) is refused and serves "
                          "nothing on Zenoh until that one leaves (ROS is served meanwhile); "
                          "stop the other robot, or give this one another --robot name",
                          self.robot, ", ".join(sorted(others)), self.zid)
            await self._until_unclaimed(session)
            # Two robots that announced the name at once each withdrew for the other: they
            # try again at different times.
            await asyncio.sleep(random.uniform(0, CLAIM_WAIT))

    async def _until_unclaimed(self, session: zenoh.Session) -> None:
        """Wait until no other robot's claim of the name is on the network: told by a
        claim going (:meth:`_on_claim`), and asked again each ``CLAIM_RECHECK`` s besides
        (Zenoh may not tell a waiting robot of a token that goes: seen once in some runs,
        the waiting robot then waited for ever)."""
        while True:
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(CLAIM_RECHECK):
                    await self._claim_changed.wait()
            self._claim_changed.clear()
            found = await tokens(session, f"{self.robot}/{keys.CLAIM}/*", CLAIM_WAIT)
            if not {keys.parse_alive(key)[1] for key in found} - {self.zid}:
                return

    def _on_claim(self, sample: zenoh.Sample) -> None:
        """Another session's token of the robot's name came or went: one gone may free the
        name for a robot waiting for it; one come while this robot holds the name is a robot
        refused (it withdraws when it sees this one's), said here too."""
        zid = keys.parse_alive(str(sample.key_expr))[1]
        if zid == self.zid:
            return
        if sample.kind != zenoh.SampleKind.PUT:
            self._claim_changed.set()
        elif self.holding and self._loop.time() < self._away_until:
            self._returned.set()  # back from an outage: another took the name meanwhile?
        elif self.holding:
            self.name_refusals += 1
            log.warning("robot %s: another robot (Zenoh id %s) announced this robot's name, "
                        "which this robot (Zenoh id %s) holds: it is refused, this one goes on "
                        "serving", self.robot, zid, self.zid)

    def _on_transport(self, event: zenoh.TransportEvent) -> None:
        """The robot's own log says when its uplink goes and comes back (its last router
        gone, or the first back): the relays' clients are told by their relays. Back, a
        robot that held its name looks whether another took it meanwhile (:meth:`_hold`)."""
        zid = str(event.transport.zid)
        if event.kind == zenoh.SampleKind.PUT:
            first = not self.uplinks
            self.uplinks.add(zid)
            if first:
                self._uplink_since = self._loop.time()
            self.uplink.transport(zid, opened=True)
            if first and self._away_until == math.inf:
                self._away_until = self._loop.time() + self.options.lease
                self._returned.set()
        elif zid in self.uplinks:
            self.uplinks.discard(zid)
            if not self.uplinks:
                self.uplink_lost += 1
                if self.holding:
                    self._away_until = math.inf
            self.uplink.transport(zid, opened=False)

    def _on_loop(self, fn: Callable[[Any], None]) -> Callable[[Any], None]:
        """A Zenoh callback that hands its argument to ``fn`` on the event loop."""
        loop = self._loop

        def cross(arg: Any) -> None:
            with contextlib.suppress(RuntimeError):  # the loop closed while Zenoh called
                loop.call_soon_threadsafe(fn, arg)

        return cross

    async def close(self) -> None:
        """Leave Zenoh (the relays see the robot go) and release what the relays held."""
        if self._runner is not None:
            self._runner.cancel()
            with contextlib.suppress(asyncio.CancelledError, BridgeError):
                await self._runner
        await self.uplink.close()
        if self.bulk is not None:
            self.bulk.close()
        self._withdraw()
        for entity in self._listeners:
            with contextlib.suppress(zenoh.ZError):
                entity.undeclare()
        self._listeners.clear()
        if self.session is not None:
            session, self.session = self.session, None
            await self._loop.run_in_executor(None, session.close)

    # -- the robot's relay policy --------------------------------------------------------------

    def refusal(self, capability: str, name: str, relay: str | None = None) -> str | None:
        """Why the policy does not let relays (``relay``, where the request says which) use
        ``capability`` on ``name`` (``None``: they may). Logged at WARNING the first time for
        each (capability, name), then counted."""
        role = self.policy()
        if role is not None and role.allows(capability, name):
            return None
        which = f"role {role.name}" if role is not None else "its role, which is gone"
        why = (f"robot {self.robot}'s relay policy ({which}) does not let relays "
               f"{capability.replace('_', ' ')} {name}")
        key = (capability, name)
        self.policy_refused[key] = self.policy_refused.get(key, 0) + 1
        if self.policy_refused[key] == 1:
            log.warning("refused %s: %s", f"relay {relay}" if relay else "a relay", why)
        return why

    def _served_in_ros(self, key: str) -> bool:
        """Whether a ROS node other than the robot's own bridge serves ``key`` (the Graph's
        own count of servers, as the bridge's ownership rule asks it)."""
        return key not in self.served and bool(self.graph.other_servers(key))

    # -- topics: demand-driven -----------------------------------------------------------------

    def _on_demand(self, sample: zenoh.Sample) -> None:
        try:
            relay, topic = keys.parse_demand(str(sample.key_expr))
        except IndexError:
            return
        export = self.exports.get(topic)
        if sample.kind == zenoh.SampleKind.PUT:
            if self.refusal("subscribe", topic, relay) is not None:
                return
            if export is None:
                export = self._export(topic)
                if export is None:
                    return
            export.relays.add(relay)
        elif export is not None:
            export.relays.discard(relay)
            if not export.relays:
                if export.replay is None:
                    self._unwatched(topic)
                elif not export.lingering:  # its relays may be cut off: keep its window
                    export.lingering = True
                    self._loop.call_later(self.demand_linger, self._linger, topic, export)

    def _linger(self, topic: str, export: _Export) -> None:
        """A replayed topic no relay watched for a while: unsubscribed once the link has
        been up ``demand_linger`` s with no relay asking for it again."""
        if self.exports.get(topic) is not export or export.relays:
            export.lingering = False
            return
        wait = self._uplink_since + self.demand_linger - self._loop.time()
        if not self.uplinks or wait > 0:  # its relays cannot say whether they still watch
            self._loop.call_later(max(wait, self.demand_linger if not self.uplinks else 0.0),
                                  self._linger, topic, export)
            return
        self._unwatched(topic)

    def _unwatched(self, topic: str) -> None:
        export = self.exports.pop(topic)
        self._unexport(export)
        self.priorities.forget(topic)
        log.info("nobody watches %s through a relay now: unsubscribed", topic)

    def _unexport(self, export: _Export) -> None:
        self.graph.unsubscribe(export.feed, export.listener)
        if export.replay is not None:
            export.replay.close()
            export.replay = None

    def _export(self, topic: str) -> _Export | None:
        key = f"{self.robot}/{topic[1:]}"

        def listener(msg: Message) -> None:
            if self.session is None:
                return
            payload, attachment = self._stamp(export, msg)
            qos = self.priorities.of(topic, len(payload), getattr(export.feed, "reliable", True))
            self.uplink.sent(len(payload))
            if qos.bulk and self.bulk is not None:  # a big topic: whole, latest wins (.bulk)
                if export.replay is not None:  # and not replayed (.replay)
                    export.replay.close()
                    export.replay = None
                self.bulk.put(key, payload, attachment, qos.kwargs)
            elif self._replayed(export, msg):
                if export.replay is None:
                    export.replay = ReplayPublisher(self.session, key, self.replay, topic,
                                                    self.replay_budget)
                export.replay.put(payload, attachment, qos)
            else:
                self.session.put(key, payload, attachment=attachment, **qos.kwargs)

        try:
            feed = self.graph.subscribe(topic, None, listener)
        except (BridgeError, ValueError) as exc:
            log.warning("a relay asked for %s, which cannot be subscribed: %s", topic, exc)
            return None
        export = self.exports[topic] = _Export(feed, listener)
        self.graph_changed()  # the type may be learned later: the bridge's refresh does it
        log.info("a relay watches %s: subscribed", topic)
        return export

    def _replayed(self, export: _Export, msg: Message) -> bool:
        """Whether ``msg`` goes through the topic's window: a reliable, volatile topic's
        (a best-effort or latched one's latest wins), with a window."""
        feed = export.feed
        return (self.replay.count > 0 and feed.latched is not msg
                and bool(getattr(export.feed, "reliable", True))
                and not getattr(feed, "transient_local", False))

    def replay_windows(self) -> dict[str, tuple[int, int]]:
        """What each replayed topic's window holds now: (messages, payload bytes)."""
        return {topic: (e.replay.held, e.replay.held_bytes)
                for topic, e in self.exports.items() if e.replay is not None}

    def metrics(self, may_see: Callable[[str], bool]) -> list[Metric]:
        """The robot's ``/metrics`` families of its replay windows (topics ``may_see``) and
        of its uplink."""
        return [*window_metrics(self.replay_windows(), may_see),
                *self.uplink.metrics(*uplink_use(self))]

    def status(self) -> dict[str, Any]:
        """The robot's ``relay_uplink`` section of ``status.json`` (:meth:`.Uplink.status`)."""
        return {"relay_uplink": self.uplink.status(*uplink_use(self))}

    def _stamp(self, export: _Export, msg: Message) -> tuple[bytes, bytes]:
        """The payload and attachment of ``msg``, numbered in its topic's stream."""
        last = export.last
        if last is not None and last[0] is msg:
            return msg.data, last[1]
        export.seq += 1
        meta = Meta(type=export.feed.type_name or "", latched=export.feed.latched is msg,
                    stamp_ns=msg.stamp_ns, epoch=export.epoch, seq=export.seq, zid=self.zid)
        attachment = meta.encode()
        export.last = (msg, attachment)
        return msg.data, attachment

    def _answer_latched(self, query: zenoh.Query) -> None:
        with answering(query):
            topic = keys.name_of(str(query.key_expr), 2)
            export = self.exports.get(topic)
            latched = export.feed.latched if export is not None else None
            if export is not None and latched is not None:
                payload, attachment = self._stamp(export, latched)
                query.reply(query.key_expr, payload, attachment=attachment)

    # -- publishing for relays' clients --------------------------------------------------------

    def _on_advertise(self, sample: zenoh.Sample) -> None:
        try:
            relay, topic, latch, type_name = keys.parse_advertise(str(sample.key_expr))
        except IndexError:
            return
        entry = (topic, type_name, latch)
        if sample.kind == zenoh.SampleKind.PUT:
            if self.refusal("publish", topic, relay) is not None:
                return
            if self._publisher(entry) is not None:
                self.publishers[entry][1].add(relay)
            return
        held = self.publishers.get(entry)
        if held is not None:
            held[1].discard(relay)
            self._release_unheld(entry)

    def _publisher(self, entry: tuple[str, str, bool]) -> Publisher | None:
        held = self.publishers.get(entry)
        if held is not None:
            return held[0]
        topic, type_name, latch = entry
        try:
            cls = self.graph.resolve_message(type_name)
            pub = self.graph.acquire_publisher(topic, cls, latch, 10)
        except (BridgeError, ValueError) as exc:
            log.warning("a relay's publisher of %s (%s) cannot be made: %s", topic, type_name,
                        exc)
            return None
        self.publishers[entry] = (pub, set())
        return pub

    def _on_in(self, sample: zenoh.Sample) -> None:
        topic = keys.name_of(str(sample.key_expr), 2)
        try:
            meta = Meta.decode(sample.attachment.to_bytes() if sample.attachment else None)
        except BridgeError as exc:
            log.warning("a message for %s from a relay is dropped: %s", topic, exc)
            return
        if self.refusal("publish", topic) is not None:
            return
        entry = (topic, meta.type, meta.latched)
        pub = self._publisher(entry)
        if pub is None:
            return
        pub.publish(sample.payload.to_bytes())
        if not self.publishers[entry][1] and entry not in self._unheld:
            self._unheld.add(entry)
            self._loop.call_later(self.unheld_wait, self._drop_unheld, entry)

    def _drop_unheld(self, entry: tuple[str, str, bool]) -> None:
        self._unheld.discard(entry)
        if self._release_unheld(entry):
            log.info("no relay advertises %s (%s): its publisher made for a message went",
                     entry[0], entry[1])

    def _release_unheld(self, entry: tuple[str, str, bool]) -> bool:
        """Release ``entry``'s publisher if no relay's token holds it (True if it went)."""
        held = self.publishers.get(entry)
        if held is None or held[1]:
            return False
        del self.publishers[entry]
        self.graph.release_publisher(held[0])
        return True

    # -- services ------------------------------------------------------------------------------

    def _answer_call(self, query: zenoh.Query) -> None:
        self._spawn(self._call(query))

    def _spawn(self, coro: Any) -> None:
        task = self._loop.create_task(coro)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def _call(self, query: zenoh.Query) -> None:
        with answering(query):
            try:
                relay, service = keys.parse_scoped(str(query.key_expr))
                req = CallRequest.decode(query.payload.to_bytes() if query.payload else b"")
                refused = self.refusal("call_service", service, relay)
                if refused is not None:
                    raise BridgeError(refused)
                response = await self.graph.call_service(
                    service, req.type, req.args, req.timeout, req.discovery_wait,
                    check=lambda request: self._not_its_goal(relay, service, request))
            except Exception as exc:  # rclpy's own (a name it refuses) too: the relay's
                query.reply_err(str(exc).encode())  # caller gets the text, not silence
                return
            query.reply(query.key_expr, _json(response))

    def _not_its_goal(self, relay: str, service: str, request: Any) -> str | None:
        """Why ``relay`` may not send ``request`` to ``service``: a call of an action's
        ``cancel_goal`` that reaches a goal another relay sent (a relay acts on its own goals
        only; a zero goal id or a stamp cancels every goal, theirs too). ``None``: it may
        (the robot's relay policy decides the rest)."""
        action = service.removesuffix(_CANCEL_SERVICE)
        theirs = [g for g in self.goals.values() if g.action == action and g.key[0] != relay]
        if action == service or not theirs:
            return None
        info = getattr(request, "goal_info", None)
        uuid = bytes(info.goal_id.uuid) if info is not None else b""
        if info is None or info.stamp.sec or info.stamp.nanosec or not any(uuid):
            owners = ", ".join(sorted({g.key[0] for g in theirs}))
            return (f"relay {relay} may not cancel every goal of {action}: a zero goal id or a "
                    f"stamp would cancel goals relay {owners} sent, and a relay acts on its own "
                    "goals only (give one goal's id and a zero stamp)")
        for goal in theirs:
            handle = goal.sent.handle if goal.sent is not None else None
            if handle is not None and bytes(handle.goal_id.uuid) == uuid:
                return (f"goal {uuid.hex()} of {action} was sent through relay {goal.key[0]}: "
                        f"relay {relay} may not cancel it (a relay acts on its own goals only)")
        return None

    # -- services relays' clients serve --------------------------------------------------------

    def _on_serve(self, sample: zenoh.Sample) -> None:
        try:
            relay, name, type_name = keys.parse_serve(str(sample.key_expr))
        except IndexError:
            return
        action = "/action/" in type_name
        key = name + _GOAL_SERVICE if action else name
        served = self.served.get(key)
        what = "action" if action else "service"
        kind: Kind = "action" if action else "srv"
        repeat = self.refusing.pop(keys.refused_key(self.robot, relay, name, kind), None)
        if repeat is not None:  # the refused token went, or comes again to be decided anew
            repeat.cancel()
        if sample.kind != zenoh.SampleKind.PUT:
            if served is not None and served.relay == relay:
                del self.served[key]
                self._unserve(key, served)
                self._refresh_snapshot()
                log.info("%s %s is no longer served through relay %s", what, name, relay)
            return
        if served is not None:
            if served.relay != relay:  # the first keeps it: the second relay's client is told
                self._refuse(relay, name, kind, f"{name} is already served by a client of "
                             f"relay {served.relay}; robot {self.robot} keeps the first")
            return
        refused = self.refusal("serve_action" if action else "serve_service", name, relay)
        if refused is None and self._served_in_ros(key) \
                and self.refusal("take_over", name, relay) is not None:
            role = self.policy()
            refused = (f"{what} {name} is served by a ROS node of robot {self.robot}, and its "
                       f"relay policy (role {role.name if role else 'gone'}) lets no relay take "
                       "it over (take_over)")
        if refused is not None:
            self._refuse(relay, name, kind, refused)
            return
        old = self._lingering.pop(key, None)
        if old is not None:  # two servers of one name would both answer each goal
            old.destroy()
        try:
            ros: ServedService | ServedAction
            if action:
                ros = self.graph.serve_action(
                    name, self.graph.resolve_action(type_name),
                    lambda goal: self._execute(name, relay, goal),
                    lambda goal: self._cancel_served(name, relay, goal))
            else:
                ros = self.graph.serve(name, self.graph.resolve_service(type_name),
                                       lambda call: self._forward(name, relay, call))
        except (BridgeError, ValueError) as exc:
            self._refuse(relay, name, kind, f"robot {self.robot} cannot serve {what} {name} "
                         f"({type_name}): {exc}")
            return
        self.served[key] = _Served(relay, type_name, ros)
        self._refresh_snapshot()
        log.info("%s %s is served through relay %s", what, name, relay)

    def _refuse(self, relay: str, name: str, kind: Kind, why: str) -> None:
        """Tell ``relay`` that its client's ``@serve`` token of ``name`` is not taken
        (``why``): its session stops serving the name and tells the client, who would
        otherwise believe it serves and get no calls."""
        log.warning("relay %s's client serves %s, refused: %s", relay, name, why)
        self._put_refusal(keys.refused_key(self.robot, relay, name, kind), why.encode(),
                          REFUSAL_REPEAT[0])

    def _put_refusal(self, key: str, why: bytes, wait: float) -> None:
        """Put a refusal, and again after ``wait`` s (doubling) until its token goes."""
        if self.session is None:
            return
        with contextlib.suppress(zenoh.ZError):
            self.session.put(key, why)
        self.refusing[key] = self._loop.call_later(
            wait, self._put_refusal, key, why, min(2 * wait, REFUSAL_REPEAT[1]))

    def _unserve(self, key: str, served: _Served) -> None:
        """A relay's client stopped serving: a service leaves ROS at once; an action's goals
        are aborted and its server lingers a moment, so ROS callers fetch those results (as
        on the bridge)."""
        ros = served.ros
        if not key.endswith(_GOAL_SERVICE):
            ros.destroy()
            return
        for goal in list(served.goals.values()):
            goal.finish(Status.ABORTED)
        served.goals.clear()
        action: ServedAction = ros  # type: ignore[assignment]
        action.alive = False
        self._lingering[key] = action
        self._loop.call_later(ACTION_LINGER, self._end_linger, key, action)

    def _end_linger(self, key: str, action: ServedAction) -> None:
        if self._lingering.get(key) is action:
            del self._lingering[key]
            action.destroy()

    def _forward(self, service: str, relay: str, call: RosCall) -> None:
        """A ROS call of a relay-served service: one query to the relay; its reply answers
        the caller, an error or no reply leaves it unanswered (as the bridge does)."""
        served = self.served.get(service)
        if served is None or served.relay != relay or self.session is None:
            log.warning("a ROS call to %s arrived after it went: not answered", service)
            return
        try:
            payload = _json(call.served.request_conv.to_obj(call.request))
        except Exception:
            log.exception("cannot convert a request to %s", service)
            return

        def answer(reply: zenoh.Reply) -> None:
            if reply.ok is None:
                text = reply.err.payload.to_string() if reply.err is not None else "?"
                log.warning("relay %s failed a call of %s (%.200s): the ROS caller is not "
                            "answered", relay, service, text)
                return
            try:
                obj = json.loads(reply.ok.payload.to_bytes())
                call.complete(call.served.response_conv.from_obj(obj, "response"))
            except (ValueError, ConversionError) as exc:
                log.warning("relay %s answered %s with a bad response (%s): the ROS caller "
                            "is not answered", relay, service, exc)

        self.session.get(keys.key_of(self.robot, service, f"{keys.SERVING}/{relay}"),
                         zenoh.handlers.Callback(self._on_loop(answer)), payload=payload,
                         timeout=SERVED_CALL_WAIT)

    def _execute(self, action: str, relay: str, goal: ServedGoal) -> None:
        """A ROS goal of a relay-served action: one query to the relay, its replies the
        goal's feedback and end; a query that ends without a result aborts the goal."""
        if self.session is None:
            goal.finish(Status.ABORTED)
            return
        gid = f"{self.epoch}{next(self._served_goal_ids)}"
        self._served_goals[id(goal)] = gid
        served = self.served.get(action + _GOAL_SERVICE)
        if served is not None:
            served.goals[id(goal)] = goal
        conv = goal.served

        def answer(reply: zenoh.Reply) -> None:
            try:
                if reply.ok is None:
                    raise BridgeError(reply.err.payload.to_string() if reply.err else "?")
                event = GoalEvent.decode(reply.ok.payload.to_bytes())
                if event.event == "feedback":
                    goal.feedback(conv.feedback_conv.from_obj(event.values, "feedback"))
                elif event.event == "result":
                    result = None
                    if event.values is not None:
                        result = conv.result_conv.from_obj(event.values, "result")
                    goal.finish(event.status, result)
            except BridgeError as exc:  # ConversionError too
                log.warning("relay %s's goal %s of %s: %s; the goal is aborted", relay, gid,
                            action, exc)
                goal.finish(Status.ABORTED)

        def ended(_: Any = None) -> None:
            self._served_goals.pop(id(goal), None)
            if served is not None:
                served.goals.pop(id(goal), None)
            if goal.finish(Status.ABORTED):
                log.warning("relay %s ended goal %s of %s without a result: aborted", relay,
                            gid, action)

        self.session.get(keys.key_of(self.robot, action, f"{keys.EXECUTING}/{relay}"),
                         zenoh.handlers.Callback(self._on_loop(answer),
                                                 lambda: self._on_loop(ended)(None)),
                         payload=Execute(gid, goal=conv.goal_conv.to_obj(goal.request)).encode(),
                         timeout=GOAL_WAIT, consolidation=zenoh.ConsolidationMode.NONE)

    def _cancel_served(self, action: str, relay: str, goal: ServedGoal) -> None:
        """A ROS caller cancels a goal of a relay-served action: the relay's client hears it
        (and decides how the goal ends)."""
        gid = self._served_goals.get(id(goal))
        if gid is not None and self.session is not None:
            self.session.get(keys.key_of(self.robot, action, f"{keys.EXECUTING}/{relay}"),
                             ignore_replies, payload=Execute(gid, cancel=True).encode(),
                             timeout=SERVED_CALL_WAIT)

    # -- actions -------------------------------------------------------------------------------

    def _answer_goal(self, query: zenoh.Query) -> None:
        self._spawn(self._goal(query))

    async def _goal(self, query: zenoh.Query) -> None:
        key: tuple[str, str] | None = None
        try:
            relay, action = keys.parse_scoped(str(query.key_expr))
            req = GoalRequest.decode(query.payload.to_bytes() if query.payload else b"")
            if req.relay != relay:  # the key's is the relay's own (the router's rules)
                raise BridgeError(f"a goal of relay {relay} names relay {req.relay} as its "
                                  "sender: a relay sends its own goals only")
            if (relay, req.id) in self.goals or (relay, req.id) in self._waiting:
                raise BridgeError(f"relay {relay}'s goal {req.id} is in flight already")
            refused = self.refusal("send_action_goal", action, req.relay)
            if refused is not None:
                raise BridgeError(refused)
            action_cls = self.graph.resolve_action(req.type)
            conv = self.graph.converter(action_cls.Goal)
            goal = conv.from_obj(args_mapping(req.goal, conv.fields, "goal"), "args")
            key = (req.relay, req.id)
            self._waiting.add(key)
            client = await self._action_client(action, action_cls, req.timeout)
        except BridgeError as exc:
            with answering(query):
                query.reply(query.key_expr, GoalEvent("failed", text=str(exc)).encode())
            return
        finally:
            if key is not None:
                self._waiting.discard(key)
        if key in self._early_cancels:  # canceled, or its relay went, while it waited
            self._early_cancels.discard(key)
            with answering(query):
                query.reply(query.key_expr, GoalEvent("result", status=Status.CANCELED).encode())
            return
        running = _RobotGoal(self, query, key, action, client)
        self.goals[key] = running
        running.sent = client.send(goal, running, req.feedback)

    async def _action_client(self, name: str, action_cls: Any, timeout: float) -> ActionClient:
        """The robot's shared client of ``name``, once a server is ready for it (at most
        ``timeout`` s)."""
        key = (name, action_cls)
        deadline = self._loop.time() + timeout
        while True:
            client = self.action_clients.get(key)
            if client is None:
                client = self.action_clients[key] = self.graph.action_client(name, action_cls)
            self._client_used[key] = self._loop.time()
            if self._sweeper is None:
                self._sweeper = self._loop.call_later(self.client_idle, self._sweep)
            if client.ready():
                return client
            if self._loop.time() >= deadline:
                raise BridgeError(f"action {name} has no action server ready on robot "
                                  f"{self.robot} within {timeout} s")
            await asyncio.sleep(0.02)

    def _sweep(self) -> None:
        """Destroy the action clients no goal used for ``client_idle`` seconds and none is
        running through (each adds entities to every wait set of the robot's executor)."""
        self._sweeper = None
        self.sweeps += 1
        now = self._loop.time()
        busy = {id(goal.client) for goal in self.goals.values()}
        for key, used in list(self._client_used.items()):
            client = self.action_clients.get(key)
            if client is None or (now - used >= self.client_idle and id(client) not in busy):
                del self._client_used[key]
                if client is not None:
                    del self.action_clients[key]
                    client.destroy()
        if self._client_used:
            self._sweeper = self._loop.call_later(self.client_idle, self._sweep)

    def _answer_cancel(self, query: zenoh.Query) -> None:
        with answering(query):
            try:
                relay, gid = str(query.key_expr).split("/")[2:4]
            except ValueError:
                return
            self._cancel((relay, gid))

    def _cancel(self, key: tuple[str, str]) -> None:
        running = self.goals.get(key)
        if running is None:  # the cancel overtook its goal: canceled when it comes
            self._early_cancels.add(key)
            if len(self._early_cancels) > 1000:
                self._early_cancels.pop()
        elif running.sent is not None:
            running.sent.cancel()

    def _on_running(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.PUT:
            return
        try:
            relay, gid = str(sample.key_expr).split("/")[2:4]
        except ValueError:
            return
        if (relay, gid) in self.goals or (relay, gid) in self._waiting:
            log.info("relay %s went with goal %s in flight: canceling it", relay, gid)
            self._cancel((relay, gid))

    # -- parameters ----------------------------------------------------------------------------

    def _answer_param(self, query: zenoh.Query) -> None:
        self._spawn(self._param(query))

    async def _param(self, query: zenoh.Query) -> None:
        with answering(query):
            node = keys.name_of(str(query.key_expr), 2)
            kind = "error"
            try:
                req = ParamRequest.decode(query.payload.to_bytes() if query.payload else b"")
                answer: Any
                if req.op != "names":
                    refused = self.refusal("params", f"{node}:{req.name}")
                    if refused is not None:
                        raise PermissionError(refused)
                if req.op == "names":
                    role = self.policy()  # names the policy hides are left out, unlogged
                    answer = [n for n in await self.graph.parameter_names(node, req.timeout)
                              if role is not None and role.allows("params", f"{node}:{n}")]
                elif req.op == "get":
                    answer = await self.graph.get_parameter(node, req.name)
                else:
                    answer = await self.graph.set_parameter(node, req.name, req.value)
                query.reply(query.key_expr, req.answer(answer))
                return
            except TimeoutError as exc:
                kind, text = "timeout", str(exc) or f"node {node} did not answer in time"
            except LookupError as exc:
                kind, text = "lookup", str(exc)
            except ValueError as exc:
                kind, text = "value", str(exc)
            except PermissionError as exc:
                kind, text = "forbidden", str(exc)
            except Exception as exc:  # the relay's caller gets the text, as the bridge's does
                text = str(exc)
            query.reply_err(_json({"kind": kind, "text": text}))

    # -- the graph -----------------------------------------------------------------------------

    def _answer_graph(self, query: zenoh.Query) -> None:
        with answering(query):
            query.reply(query.key_expr, self._snapshot_bytes, attachment=self.zid.encode())

    def _refresh_snapshot(self) -> None:
        try:
            snap = self._take_snapshot()
        except Exception:  # a graph query failed while a node left: try again next time
            log.debug("the graph snapshot failed", exc_info=True)
            return
        data = snap.encode()
        if data != self._snapshot_bytes and self.session is not None:
            self.snapshot, self._snapshot_bytes = snap, data
            self.session.put(f"{self.robot}/{keys.GRAPH}", data, attachment=self.zid.encode())

    def _take_snapshot(self) -> Snapshot:
        return self.graph_snapshots.take({name: s.relay for name, s in self.served.items()})


def _report(task: asyncio.Task[None]) -> None:
    if not task.cancelled() and task.exception() is not None:
        log.error("the robot left Zenoh: %s", task.exception())




def _json(obj: Any) -> bytes:
    return json.dumps(obj, separators=(",", ":")).encode()
