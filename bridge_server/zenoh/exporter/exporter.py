"""The robot's :class:`Exporter`: its parts (:mod:`.topics`, :mod:`.publishing`,
:mod:`.services`, :mod:`.served`, :mod:`.actions`, :mod:`.parameters`, :mod:`.graph`,
:mod:`.presence`, all held to :mod:`.policy`) put together, with its life: dialing out,
holding the robot's name, offering the robot while it holds it, withdrawing, leaving."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import math
import secrets
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import zenoh

from bridge_server.zenoh import keys
from bridge_server.zenoh.bulk import BulkSender
from bridge_server.zenoh.exporter.actions import RelayGoals
from bridge_server.zenoh.exporter.base import log
from bridge_server.zenoh.exporter.parameters import Parameters
from bridge_server.zenoh.exporter.policy import DEFAULT_POLICY
from bridge_server.zenoh.exporter.presence import CLAIM_WAIT, RETURN_POLL, Presence
from bridge_server.zenoh.exporter.publishing import UNHELD_PUBLISHER_WAIT, Publishing
from bridge_server.zenoh.exporter.served import ServedNames
from bridge_server.zenoh.exporter.services import ServiceCalls
from bridge_server.zenoh.exporter.topics import TopicExports
from bridge_server.zenoh.keys import Snapshot
from bridge_server.zenoh.link import ZenohOptions, open_session, tokens
from bridge_server.zenoh.priority import Priorities, TopicPriority
from bridge_server.zenoh.putter import Putter
from bridge_server.zenoh.replay import (
    DEMAND_LINGER,
    ReplayBudget,
    ReplayWindow,
    settle_aside,
    window_metrics,
)
from bridge_server.zenoh.robot_graph import GraphSnapshots
from bridge_server.zenoh.uplink import Uplink, uplink_use
from rosbridge_core.graph import Graph
from rosbridge_core.interfaces import BridgeError
from rosbridge_core.security.permissions import Role
from rosbridge_core.session.actions import CLIENT_IDLE

if TYPE_CHECKING:
    from prometheus_client.core import Metric

__all__ = ["DIAL_WARNING", "SNAPSHOT_INTERVAL", "Exporter"]

SNAPSHOT_INTERVAL = 1.0
"""Seconds between two looks at the ROS graph (a changed one is put at once)."""

DIAL_WARNING = 4.0
"""Seconds the robot dials without any router answering before it says so (and again
after each as many)."""


class Exporter(TopicExports, Publishing, ServiceCalls, ServedNames, RelayGoals, Parameters,
               Presence):
    """The robot ``robot``'s Graph offered on Zenoh (see the package's text)."""

    snapshot_interval: float
    _entities: list[Any]
    _runner: asyncio.Task[None] | None
    _listeners: list[Any]  # the uplink's and the name's, while the session is

    def __init__(self, graph: Graph, robot: str, options: ZenohOptions,
                 graph_changed: Callable[[], None] = lambda: None,
                 snapshot_interval: float = SNAPSHOT_INTERVAL,
                 policy: Callable[[], Role | None] = lambda: DEFAULT_POLICY,
                 replay: ReplayWindow | None = None,
                 priorities: dict[str, TopicPriority] | None = None) -> None:
        self.graph = graph
        self.priorities = Priorities(priorities)
        self.uplink = Uplink(robot, options)
        self.bulk = None
        self.putter = Putter()
        self.replay = replay or ReplayWindow()
        self.replay_budget = ReplayBudget(self.replay.total)
        self.demand_linger = DEMAND_LINGER
        self.policy = policy
        self.policy_refused = {}
        self.robot = keys.check_robot(robot)
        self.options = options
        self.graph_changed = graph_changed
        self.snapshot_interval = snapshot_interval
        self.epoch = secrets.token_hex(6)
        self.session = None
        self.exports = {}
        self.publishers = {}
        self.unheld_wait = UNHELD_PUBLISHER_WAIT
        self._unheld = set()
        self.action_clients = {}
        self.client_idle = CLIENT_IDLE
        self.sweeps = 0
        self._client_used = {}
        self._sweeper = None
        self.goals = {}
        self._early_cancels = set()
        self._waiting = set()
        self.served = {}
        self._served_goals = {}
        self.refusing = {}
        self._lingering = {}
        self._served_goal_ids = itertools.count()
        self.snapshot = Snapshot()
        self._snapshot_bytes = b""
        self.graph_snapshots = GraphSnapshots(graph)
        self._entities = []
        self._tasks = set()
        self._loop = asyncio.get_running_loop()
        self._runner = None
        self.uplinks = set()
        self.uplink_lost = 0
        self._uplink_since = 0.0
        self.zid = ""
        self.holding = False
        self.refused_by = set()
        self.name_refusals = 0
        self._claim_changed = asyncio.Event()
        self._listeners = []
        self._away_until = 0.0
        self._returned = asyncio.Event()

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
        self.zid = str(session.zid())
        self.uplink.watch(session, self.zid)
        self._listeners = [
            session.info.declare_transport_events_listener(self._on_loop(self._on_transport),
                                                           history=True),
            session.liveliness().declare_subscriber(f"{self.robot}/{keys.CLAIM}/*",
                                                    self._on_loop(self._on_claim)),
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
        another robot's claim: that robot took the name meanwhile, and the held claim wins.
        Back from an outage it looks at once, then after :data:`RETURN_POLL` s, each wait
        twice the one before, and at the end of its time away (:data:`RETURN_LEASES`
        leases). The looks do not look at the graph more often than every
        ``snapshot_interval`` s: 250 simulated robots back from a router's restart spent
        half their process's loop taking snapshots at each look, and held their names again
        7.6 s after the router was back."""
        look = self._loop.time() + self.snapshot_interval  # the graph's next look
        away, gap = 0.0, RETURN_POLL  # the outage the looks are for; the next wait
        while True:
            now = self._loop.time()
            back = now < self._away_until < math.inf
            if back and away != self._away_until:  # back from another outage
                away, gap = self._away_until, RETURN_POLL
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(min(gap, self._away_until - now) if back
                                           else max(0.0, look - now)):
                    await self._returned.wait()
            if self._returned.is_set() or back:
                if not self._returned.is_set():
                    gap *= 2
                self._returned.clear()
                found = await tokens(session, f"{self.robot}/{keys.CLAIM}/*", CLAIM_WAIT)
                if {keys.parse_alive(key)[1] for key in found} - {self.zid}:
                    return self._entities[0]
            if self._loop.time() >= look:
                self._refresh_snapshot()
                look = self._loop.time() + self.snapshot_interval

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

    async def close(self) -> None:
        """Leave Zenoh (the relays see the robot go) and release what the relays held."""
        if self._runner is not None:
            self._runner.cancel()
            with contextlib.suppress(asyncio.CancelledError, BridgeError):
                await self._runner
        await self.uplink.close()
        self._withdraw()
        await self._loop.run_in_executor(None, self.putter.close)
        if self.bulk is not None:
            self.bulk.close()
        for entity in self._listeners:
            with contextlib.suppress(zenoh.ZError):
                entity.undeclare()
        self._listeners.clear()
        if self.session is not None:
            session, self.session = self.session, None
            await self._loop.run_in_executor(None, settle_aside)
            await self._loop.run_in_executor(None, session.close)

    # -- what the robot tells of its link ----------------------------------------------------------

    def metrics(self, may_see: Callable[[str], bool]) -> list[Metric]:
        """The robot's ``/metrics`` families of its replay windows (topics ``may_see``) and
        of its uplink."""
        return [*window_metrics(self.replay_windows(), may_see),
                *self.uplink.metrics(*uplink_use(self))]

    def status(self) -> dict[str, Any]:
        """The robot's ``relay_uplink`` section of ``status.json`` (:meth:`.Uplink.status`)."""
        return {"relay_uplink": self.uplink.status(*uplink_use(self))}


def _report(task: asyncio.Task[None]) -> None:
    if not task.cancelled() and task.exception() is not None:
        log.error("the robot left Zenoh: %s", task.exception())

