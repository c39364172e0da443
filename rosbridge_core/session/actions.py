"""What one session does with actions: goals it sends, and actions it serves.

A :class:`SessionActions` belongs to one :class:`~rosbridge_core.session.Session`
(``session.actions``), which hands it the action ops listed in
:attr:`SessionActions.OPS` and calls :meth:`SessionActions.close` when the client
goes away. The ROS side is the session's :class:`~rosbridge_core.graph.Graph` (on
rclpy: :mod:`bridge_server.rclpy_graph.actions`).

Its two halves: :class:`~rosbridge_core.session.goals.GoalSending` (``send_action_goal``,
``cancel_action_goal``, and the cancel service called as a plain service; see
:mod:`rosbridge_core.session.goals`) and
:class:`~rosbridge_core.session.served_actions.ActionServing` (``advertise_action`` and the
ROS goals the client carries out; see :mod:`rosbridge_core.session.served_actions`).
"""

from __future__ import annotations

import itertools
from typing import TYPE_CHECKING, ClassVar

from rosbridge_core.protocol import ops
from rosbridge_core.protocol.names import absolute_name
from rosbridge_core.session.goals import CLIENT_IDLE, ActionClients, ClientGoal, GoalSending
from rosbridge_core.session.limits import over_cap
from rosbridge_core.session.served_actions import ACTION_LINGER, ActionServing, ClientAction

if TYPE_CHECKING:
    from rosbridge_core.security import Gate
    from rosbridge_core.session.host import SessionView

__all__ = ["ACTION_LINGER", "CLIENT_IDLE", "ActionClients", "SessionActions"]


class SessionActions(GoalSending, ActionServing):
    """One client's goals in flight and served actions."""

    OPS: ClassVar[dict[type[ops.Op], str]] = {
        ops.SendActionGoal: "send_goal",
        ops.CancelActionGoal: "cancel_goal",
        ops.ActionFeedback: "feedback",
        ops.ActionResultOp: "result",
        ops.AdvertiseAction: "advertise",
        ops.UnadvertiseAction: "unadvertise",
    }
    """The ops this capability carries out, and the method for each."""
    LIMITS: ClassVar[dict[type[ops.Op], str]] = {
        ops.SendActionGoal: "goal_limit",
        ops.AdvertiseAction: "serve_limit",
    }
    """The ops that add to what the connection holds, and the method that checks each."""

    def goal_limit(self, op: ops.SendActionGoal) -> str | None:
        """Why one more goal in flight would pass the connection's limits (goals are keyed
        by goal id, so every new goal counts)."""
        return over_cap(self.goals, absolute_name(op.action), self.session.limits.max_goals,
                        "goals in flight")

    def serve_limit(self, op: ops.AdvertiseAction) -> str | None:
        """Why serving one more action (each an rclpy action server) would pass the limits."""
        return over_cap(self.served, absolute_name(op.action), self.session.limits.max_services,
                        "served actions")

    def __init__(self, session: SessionView) -> None:
        self.session = session
        self.goals: dict[str, ClientGoal] = {}
        self.served: dict[str, ClientAction] = {}
        self._owners = session.shared.action_owners
        self._goal_ids = itertools.count()


    async def close(self) -> None:
        """The client went away: cancel its goals on the ROS side, abort the goals it served."""
        for goal in list(self.goals.values()):
            self.finish(goal, "canceled")
            if goal.task is not None:
                goal.task.cancel()
            if goal.sent is not None:
                goal.sent.cancel()
        for served in list(self.served.values()):
            self.remove_served(served, "the client that served it disconnected")
        self.served.clear()

    def recheck(self, gate: Gate) -> int:
        """Stop serving the actions the role no longer allows; how many ended."""
        return self._owners.recheck(self, gate)
