"""A robot's actions on the relay: :class:`ZenohActionClient` and its
:class:`ZenohSentGoal` (a goal is one query whose replies are its events), and
:class:`ZenohServedAction` with its :class:`ZenohServedGoal` (an action a client of this
relay serves on the robot)."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import secrets
from collections.abc import Callable
from typing import Any

import zenoh

from bridge_server.zenoh import keys
from bridge_server.zenoh.graph.robot import Robot
from bridge_server.zenoh.graph.services import ServedHere
from bridge_server.zenoh.inbox import direct
from bridge_server.zenoh.keys import GOAL_WAIT, Execute, GoalEvent, GoalRequest
from bridge_server.zenoh.link import answering, ignore_replies
from rosbridge_core.graph import GoalListener, ServedGoal
from rosbridge_core.interfaces import BridgeError, ConversionError
from rosbridge_core.protocol.goal_status import GoalStatus

log = logging.getLogger("bridge_server.zenoh.graph")

__all__ = ["ZenohActionClient", "ZenohSentGoal", "ZenohServedAction", "ZenohServedGoal"]

SERVER_WAIT = 5.0
"""Seconds the robot waits for its action client to be ready for a goal (the relay's
session already waited for the robot's graph to list the action server)."""


class _GoalId:
    """A goal's id in ROS, as the sessions read it (``handle.goal_id.uuid``)."""

    def __init__(self, uuid: bytes) -> None:
        self.uuid = uuid


class _GoalHandle:
    """The robot's answer to a goal, as far as the sessions look at it."""

    def __init__(self, uuid: bytes) -> None:
        self.goal_id = _GoalId(uuid)


class ZenohSentGoal:
    """A goal sent to the robot: one query, its replies the goal's events, and a liveliness
    token (``@running``) that takes the goal (canceled by the robot) with this relay."""

    def __init__(self, shared: ZenohActionClient, listener: GoalListener) -> None:
        self.shared = shared
        self.listener = listener
        self.handle: _GoalHandle | None = None
        self.finished = False
        graph = shared.graph
        self.id = f"{secrets.token_hex(4)}{next(graph.goal_ids)}"
        self.token: Any = None

    def cancel(self) -> None:
        """Ask the robot to cancel the goal (the answer comes among the goal's replies)."""
        if not self.finished:
            graph = self.shared.graph
            with contextlib.suppress(zenoh.ZError):  # the relay is closing: the robot cancels
                graph.session.get(f"{graph.robot}/{keys.CANCEL}/{graph.relay}/{self.id}",
                                  direct(ignore_replies), timeout=SERVER_WAIT)

    def on_reply(self, reply: zenoh.Reply) -> None:
        """One of the robot's replies (on the loop)."""
        if self.finished:
            return
        if reply.ok is None:
            text = reply.err.payload.to_string() if reply.err is not None else "?"
            self._end()
            self.listener.on_failed(f"robot {self.shared.graph.robot}: {text}")
            return
        try:
            event = GoalEvent.decode(reply.ok.payload.to_bytes())
            self._dispatch(event)
        except BridgeError as exc:
            self.shared.graph.faults.add("bad_replies", f"a goal's reply dropped: {exc}")

    def _dispatch(self, event: GoalEvent) -> None:
        listener = self.listener
        shared = self.shared
        if event.event == "accepted":
            self.handle = _GoalHandle(bytes.fromhex(event.uuid))
            listener.on_accepted()
        elif event.event == "feedback":
            listener.on_feedback(shared.feedback_conv.from_obj(event.values, "feedback"))
        elif event.event == "cancel":
            listener.on_cancel_answer(event.code)
        else:
            self._end()
            if event.event == "rejected":
                listener.on_rejected()
            elif event.event == "failed":
                listener.on_failed(event.text)
            else:
                try:
                    result = None
                    if event.values is not None:
                        result = shared.result_conv.from_obj(event.values, "result")
                except ConversionError as exc:  # the goal ended all the same: say why so
                    listener.on_failed(f"robot {shared.graph.robot} sent a result that does "
                                       f"not fit {shared.type_name}: {exc}")
                    return
                listener.on_result(event.status, result)

    def on_end(self) -> None:
        """The query ended (on the loop): without a result, the robot went (or is not
        there: :meth:`~.zenoh_graph.ZenohGraph.unanswered` says which)."""
        if not self.finished:
            self._end()
            told = self.shared.graph.loop.create_task(self.shared.graph.unanswered("goal"))
            told.add_done_callback(self._told)

    def _told(self, task: asyncio.Task[str]) -> None:
        if not task.cancelled():  # cancelled: the relay is closing
            self.listener.on_failed(task.result())

    def gone(self) -> None:
        """The robot went with the goal in flight (:meth:`~.zenoh_graph.ZenohGraph.went`): it
        fails now, and the robot, if it comes back, cancels it (this relay's ``@running``
        token goes)."""
        if not self.finished:
            self._end()
            self.listener.on_failed(self.shared.graph.went("goal"))

    def _end(self) -> None:
        self.finished = True
        self.shared.graph.in_flight.discard(self.gone)
        if self.token is not None:
            with contextlib.suppress(zenoh.ZError):
                self.token.undeclare()


class ZenohActionClient:
    """The relay's client of one action of the robot (the robot's own client sends goals)."""

    def __init__(self, graph: Robot, name: str, action_cls: Any) -> None:
        self.graph = graph
        self.name = name
        self.action_cls = action_cls
        self.type_name = action_cls._type
        self.goal_conv = graph.converter(action_cls.Goal)
        self.feedback_conv = graph.converter(action_cls.Feedback)
        self.result_conv = graph.converter(action_cls.Result)

    def matched(self) -> bool:
        """Whether the robot is here and its graph lists a server of the action."""
        return self.graph.alive and bool(self.graph.server_types(
            self.name + "/_action/send_goal"))

    def ready(self) -> bool:
        """As :meth:`matched`: the robot itself waits for its client to be ready."""
        return self.matched()

    def send(self, goal: Any, listener: GoalListener, feedback: bool) -> ZenohSentGoal:
        """One query to the robot (see :class:`ZenohSentGoal`)."""
        graph = self.graph
        sent = ZenohSentGoal(self, listener)
        request = GoalRequest(type=self.type_name, goal=self.goal_conv.to_obj(goal),
                              feedback=feedback, relay=graph.relay, id=sent.id,
                              timeout=SERVER_WAIT)
        try:
            sent.token = graph.session.liveliness().declare_token(
                f"{graph.robot}/{keys.RUNNING}/{graph.relay}/{sent.id}")
            graph.session.get(keys.key_of(graph.robot, self.name, f"{keys.GOAL}/{graph.relay}"),
                              direct(graph.on_loop(sent.on_reply), graph.inbox.end(sent.on_end)),
                              payload=request.encode(), timeout=GOAL_WAIT,
                              consolidation=zenoh.ConsolidationMode.NONE)
        except zenoh.ZError:  # the relay's Zenoh session closed: the goal ends unsent
            graph.loop.call_soon(sent.on_end)
            return sent
        graph.in_flight.add(sent.gone)
        return sent

    def destroy(self) -> None:
        """Nothing to remove: each goal holds its own query and token."""



class ZenohServedGoal:
    """A ROS goal on the robot that a client of this relay carries out: its feedback and end
    are replies to the robot's query."""

    def __init__(self, served: ZenohServedAction, gid: str, request: Any,
                 query: zenoh.Query) -> None:
        self.served = served
        self.id = gid
        self.request = request
        self.query: zenoh.Query | None = query

    def feedback(self, msg: Any) -> None:
        """One feedback message to the robot, which publishes it."""
        if self.query is not None:
            with contextlib.suppress(zenoh.ZError):
                self.query.reply(self.query.key_expr, GoalEvent(
                    "feedback", values=self.served.feedback_conv.to_obj(msg)).encode())

    def finish(self, status: int, result: Any | None = None) -> bool:
        """End the goal on the robot with ``status`` and ``result``; False if it had ended."""
        query, self.query = self.query, None
        if query is None:
            return False
        self.served.goals.pop(self.id, None)
        values = self.served.result_conv.to_obj(result) if result is not None else None
        with contextlib.suppress(zenoh.ZError):
            query.reply(query.key_expr, GoalEvent("result", status=int(status),
                                                  values=values).encode())
        query.drop()  # type: ignore[no-untyped-call]
        return True


class ZenohServedAction(ServedHere):
    """An action of the robot that a client of this relay serves (``@executing``): each ROS
    goal comes as a query whose replies are its feedback and end; a ROS cancel is a query."""

    def __init__(self, graph: Robot, name: str, action_cls: Any,
                 on_goal: Callable[[ServedGoal], None],
                 on_cancel: Callable[[ServedGoal], None],
                 on_refused: Callable[[str], None] | None = None) -> None:
        super().__init__(graph, name, on_refused)
        self.alive = True
        self.goal_conv = graph.converter(action_cls.Goal)
        self.feedback_conv = graph.converter(action_cls.Feedback)
        self.result_conv = graph.converter(action_cls.Result)
        self.on_goal = on_goal
        self.on_cancel = on_cancel
        self.goals: dict[str, ZenohServedGoal] = {}
        self._declare(keys.EXECUTING, action_cls._type, "action")

    def _on_query(self, query: zenoh.Query) -> None:
        try:
            req = Execute.decode(query.payload.to_bytes() if query.payload else b"")
        except BridgeError as exc:
            with answering(query):
                query.reply_err(str(exc).encode())
            return
        if req.cancel:
            with answering(query):
                goal = self.goals.get(req.id)
                if goal is not None:
                    self.on_cancel(goal)
            return
        try:
            request = self.goal_conv.from_obj(req.goal, "goal")
        except ConversionError as exc:
            log.warning("a goal of %s from robot %s does not fit: %s", self.name,
                        self.graph.robot, exc)
            request = None
        goal = ZenohServedGoal(self, req.id, request, query)
        if request is None or not self.alive:
            goal.finish(GoalStatus.ABORTED)
            return
        self.goals[req.id] = goal
        self.on_goal(goal)

    def destroy(self) -> None:
        """The robot's action server goes (with the token); open goals are aborted."""
        self.alive = False
        for goal in list(self.goals.values()):
            goal.finish(GoalStatus.ABORTED)
        if self.graph.served_actions.get(self.name) is self:
            del self.graph.served_actions[self.name]
        self._undeclare()
        self.graph.release_types()

