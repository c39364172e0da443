"""Actions one session serves: ``advertise_action`` and the ROS goals it carries out
(:class:`ActionServing`, the serving half of
:class:`~rosbridge_core.session.actions.SessionActions`), each action as :class:`ClientAction`.

Serving actions
---------------
``advertise_action`` creates an rclpy action server. Every ROS goal is
accepted, set EXECUTING and handed to the client as ``send_action_goal`` with
id ``action_goal:<action>:<n>`` and ``feedback: true``; a ROS cancel request
arrives as ``cancel_action_goal`` with that id. The client answers with
``action_feedback`` (published) and one ``action_result``: ``status`` 4, 5
or 6 ends the goal that way; without a status, ``result`` true means
SUCCEEDED and false ABORTED. A result that does not fit the type, an
unadvertise, a disconnect or ``goal_timeout`` abort the goal at once. A name
another client serves stays with its first owner, as for services
(:mod:`rosbridge_core.session.ownership`); a taken-over owner's goals are aborted and it
gets a warning.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from rosbridge_core.graph import ACTIVE
from rosbridge_core.interfaces import ConversionError, canonical_name
from rosbridge_core.protocol import ops
from rosbridge_core.protocol.goal_status import GoalStatus
from rosbridge_core.protocol.names import absolute_name
from rosbridge_core.session.goals import GOAL_SUFFIX

if TYPE_CHECKING:
    from rosbridge_core.graph import ServedAction, ServedGoal
    from rosbridge_core.session.host import SessionView
    from rosbridge_core.session.ownership import Ownership

__all__ = ["ACTION_LINGER", "ActionServing", "ClientAction"]

log = logging.getLogger("bridge_server.session.actions")

ACTION_LINGER = 1.0
"""Seconds an unadvertised action server stays in ROS, so callers fetch the aborted results."""


class ClientAction:
    """An action this client serves, and the ROS goals it is carrying out."""

    def __init__(self, name: str, spelled: str, type_name: str) -> None:
        self.name = name
        self.spelled = spelled
        self.type_name = type_name
        self.ros: ServedAction | None = None
        self.goals: dict[str, tuple[ServedGoal, asyncio.TimerHandle | None]] = {}
        self.ids: dict[int, str] = {}  # id(ServedGoal) -> goal id, for ROS cancel requests


class ActionServing:
    """The actions one client serves (the serving half of
    :class:`~rosbridge_core.session.actions.SessionActions`)."""

    session: SessionView
    served: dict[str, ClientAction]
    _owners: Ownership[Any]
    _goal_ids: itertools.count[int]

    def advertise(self, op: ops.AdvertiseAction) -> None:
        """Serve an action from this client (an rclpy action server in the bridge)."""
        session = self.session
        name = absolute_name(op.action)
        action_cls = session.graph.resolve_action(op.type)
        type_name = canonical_name(op.type, "action")
        mine = self.served.get(name)
        if mine is not None:
            if mine.type_name == type_name:
                return
            self.remove_served(mine, "the client advertised it again with another type", False)
            del self.served[name]
        old = session.shared.action_clients.lingering.pop(name, None)
        if old is not None:  # two servers of one name would both answer each goal
            old.destroy()
        goal_service = name + GOAL_SUFFIX

        def ros_servers() -> list[str]:  # our own lingering server is not another's
            if old is not None or not session.graph.server_types(goal_service):
                return []
            return session.graph.other_servers(goal_service)

        if not self._owners.admit(self, op, name, ros_servers):
            return
        served = ClientAction(name, op.action, type_name)
        served.ros = session.graph.serve_action(
            name, action_cls,
            lambda goal: self._on_ros_goal(served, goal),
            lambda goal: self._on_ros_cancel(served, goal),
            lambda why: self._refused(served, op, why),
        )
        self.served[name] = served
        self._owners.take(name, self)

    def _refused(self, served: ClientAction, op: ops.AdvertiseAction, why: str) -> None:
        """The graph refused the name after all (a relay's robot keeps another relay's
        client): stop serving it, and refuse the advertise as a second client's is."""
        if self.served.get(served.name) is served:
            del self.served[served.name]
            self.remove_served(served, why, linger=False)
            self.session.error(f"{op.OP}: {why}", op.id)

    def _on_ros_goal(self, served: ClientAction, goal: ServedGoal) -> None:
        session = self.session
        if self.served.get(served.name) is not served or session.closed:
            goal.finish(GoalStatus.ABORTED)
            return
        gid = f"action_goal:{served.spelled}:{next(self._goal_ids)}"
        try:
            args = goal.served.goal_conv.to_obj(goal.request)
        except Exception:
            log.exception("cannot convert a goal of %s", served.name)
            goal.finish(GoalStatus.ABORTED)
            return
        timer = None
        timeout = session.config.goal_timeout
        if timeout > 0:
            timer = session.loop.call_later(timeout, self._served_expired, served, gid, timeout)
        served.goals[gid] = (goal, timer)
        served.ids[id(goal)] = gid
        session.send_op(
            ops.SendActionGoal(action=served.spelled, action_type=served.type_name, args=args,
                               id=gid, feedback=True)
        )

    def _on_ros_cancel(self, served: ClientAction, goal: ServedGoal) -> None:
        gid = served.ids.get(id(goal))
        if gid is not None and gid in served.goals:
            self.session.send_op(ops.CancelActionGoal(id=gid, action=served.spelled))

    def _served_expired(self, served: ClientAction, gid: str, timeout: float) -> None:
        entry = self._pop_goal(served, gid)
        if entry is None:
            return
        log.error("session %d: goal %s not finished within %s s; aborting it",
                  self.session.sid, gid, timeout)
        entry.finish(GoalStatus.ABORTED)
        self.session.send_op(ops.CancelActionGoal(id=gid, action=served.spelled))
        self.session.status("error", f"goal {gid} timed out after {timeout} s and was aborted",
                            gid)

    def _pop_goal(self, served: ClientAction, gid: str) -> ServedGoal | None:
        entry = served.goals.pop(gid, None)
        if entry is None:
            return None
        goal, timer = entry
        served.ids.pop(id(goal), None)
        if timer is not None:
            timer.cancel()
        return goal

    def _find(self, op: ops.ActionFeedback | ops.ActionResultOp) -> tuple[ClientAction, str] | None:
        gid = str(op.id)
        served = self.served.get(absolute_name(op.action))
        if served is not None and gid in served.goals:
            return served, gid
        for s in self.served.values():
            if gid in s.goals:
                return s, gid
        self.session.error(
            f"{op.OP}: no goal {op.id!r} of {absolute_name(op.action)} is waiting on this "
            "client", op.id
        )
        return None

    def feedback(self, op: ops.ActionFeedback) -> None:
        """The serving client's feedback for a ROS goal: publish it."""
        found = self._find(op)
        if found is None:
            return
        served, gid = found
        goal = served.goals[gid][0]
        try:
            msg = goal.served.feedback_conv.from_obj(op.values, "values")
        except ConversionError as exc:
            self.session.error(f"action_feedback for {served.name}: {exc}", op.id)
            return
        goal.feedback(msg)

    def result(self, op: ops.ActionResultOp) -> None:
        """The serving client ends a ROS goal."""
        found = self._find(op)
        if found is None:
            return
        served, gid = found
        goal = self._pop_goal(served, gid)
        assert goal is not None
        status = op.status
        if status is None:
            status = GoalStatus.SUCCEEDED if op.result else GoalStatus.ABORTED
        elif status in ACTIVE or status not in (GoalStatus.SUCCEEDED, GoalStatus.CANCELED,
                                                GoalStatus.ABORTED):
            self.session.error(
                f"action_result for {served.name}: status {status} is not a final status "
                "(4 succeeded, 5 canceled, 6 aborted); the goal was aborted",
                op.id,
            )
            status = GoalStatus.ABORTED
        elif not op.result and status == GoalStatus.SUCCEEDED:
            status = GoalStatus.ABORTED
        result = None
        if isinstance(op.values, Mapping):
            try:
                result = goal.served.result_conv.from_obj(op.values, "values")
            except ConversionError as exc:
                self.session.error(
                    f"action_result for {served.name}: {exc}; the goal was aborted", op.id
                )
                status, result = GoalStatus.ABORTED, None
        elif op.values is not None and status != GoalStatus.SUCCEEDED:
            log.info("session %d: goal %s ended (status %d): %s", self.session.sid, gid, status,
                     op.values)
        goal.finish(status, result)

    def unadvertise(self, op: ops.UnadvertiseAction) -> None:
        """Stop serving an action; its goals are aborted at once."""
        self._owners.unadvertise(self, op, absolute_name(op.action))

    def drop_served(self, name: str, why: str) -> None:
        """Another client took the action over: forget it here."""
        served = self.served.pop(name, None)
        if served is not None:
            self.remove_served(served, why, linger=False)
            self.session.status("warning", f"action {name}: {why}")

    def remove_served(self, served: ClientAction, why: str, linger: bool = True) -> None:
        """Stop serving ``served``: its goals are aborted; the rclpy server lingers a moment
        (``linger``) so that callers still see a server while the name changes hands."""
        for gid in list(served.goals):
            goal = self._pop_goal(served, gid)
            if goal is not None:
                log.error("goal %s aborted: %s", gid, why)
                goal.finish(GoalStatus.ABORTED)
        ros = served.ros
        served.ros = None
        if ros is not None:
            ros.alive = False  # new goals are rejected while it lingers
            if linger:
                lingering = self.session.shared.action_clients.lingering
                lingering[served.name] = ros
                self.session.loop.call_later(ACTION_LINGER, _end_linger, lingering, served.name,
                                             ros)
            else:
                ros.destroy()
        self._owners.release(served.name, self)


def _end_linger(lingering: dict[str, ServedAction], name: str, ros: ServedAction) -> None:
    if lingering.get(name) is ros:
        del lingering[name]
        ros.destroy()
