"""Relays' goals: a goal is a query whose replies stream what the Graph's own action client
reports (accepted, feedback, the result); a cancel is a query; a goal whose relay's
``@running`` token goes (the relay died) is canceled, as the bridge cancels a leaving
client's goals. The robot's action clients are shared by (action, type), and one no goal
used for a while is destroyed, as the bridge's are."""

from __future__ import annotations

import asyncio
import contextlib
from typing import Any

import zenoh

from bridge_server.zenoh import keys
from bridge_server.zenoh.exporter.base import log
from bridge_server.zenoh.exporter.policy import RelayPolicy
from bridge_server.zenoh.keys import GoalEvent, GoalRequest
from bridge_server.zenoh.link import answering
from rosbridge_core.graph import ActionClient, SentGoal
from rosbridge_core.interfaces import BridgeError, args_mapping
from rosbridge_core.protocol.goal_status import GoalStatus

__all__ = ["RelayGoals", "RobotGoal"]


class RobotGoal:
    """A relay's goal on the robot: what the Graph's action client reports goes back as
    replies to the goal's query (the :class:`~rosbridge_core.graph.GoalListener`)."""

    def __init__(self, exporter: RelayGoals, query: zenoh.Query, key: tuple[str, str],
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


class RelayGoals(RelayPolicy):
    """The exporter's part that runs relays' goals through the robot's action clients."""

    action_clients: dict[tuple[str, Any], ActionClient]
    """The robot's action clients of relays' goals by (action, type); one no goal used
    for ``client_idle`` seconds is destroyed, as the bridge's are."""
    client_idle: float
    sweeps: int
    """How many times idle action clients were looked for."""
    _client_used: dict[tuple[str, Any], float]
    _sweeper: asyncio.TimerHandle | None
    goals: dict[tuple[str, str], RobotGoal]
    """Relays' goals in flight by (relay id, goal id)."""
    _early_cancels: set[tuple[str, str]]
    _waiting: set[tuple[str, str]]
    """Relays' goals waiting for a ready action server (not sent yet)."""

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
                query.reply(query.key_expr,
                            GoalEvent("result", status=GoalStatus.CANCELED).encode())
            return
        running = RobotGoal(self, query, key, action, client)
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
