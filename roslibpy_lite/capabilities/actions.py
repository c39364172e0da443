"""Actions: send goals (``send_goal``) and serve actions (``advertise_action``).

The handles and the rules are in :mod:`roslibpy_lite.actions`.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import logging
from collections.abc import Coroutine, Mapping
from typing import Any

from msgs.runtime import Action, Message
from rosbridge_core.protocol import ops

from .._api_types import DEFAULT_CALL_TIMEOUT, ConnectionState
from ..actions import (
    ActionHandler,
    ActionServer,
    FeedbackCallback,
    GoalContext,
    GoalHandle,
    GoalStatus,
    _action_class,
    _part,
    action_type,
)
from ..exceptions import ConnectionClosed, Disconnected, UsageError
from ..messages import check_dict, check_name, to_wire
from . import ServingHost, Tracked

__all__ = ["Actions"]

log = logging.getLogger("roslibpy_lite.client")

_RECENT_FAILED = 64  # failed goals whose late status errors are still recognised


class Actions:
    """One client's goals in flight and the actions it serves."""

    def __init__(self, host: ServingHost) -> None:
        self.host = host
        self.goals: dict[str, GoalHandle] = {}
        self.servers: dict[str, ActionServer] = {}
        self.served_goals: dict[str, tuple[GoalContext, asyncio.Task[None]]] = {}
        self._failed_goals: collections.deque[str] = collections.deque()
        host.route(ops.ActionFeedback, self._on_feedback)
        host.route(ops.ActionResultOp, self._on_result)
        host.route(ops.SendActionGoal, self._serve_goal)
        host.route(ops.CancelActionGoal, self._on_cancel_goal)
        host.on_restore(self._restore)
        host.on_drop(self._drop)

    @property
    def validate(self) -> bool:
        """Whether dicts are checked against their type's ``msgs`` class."""
        return self.host.validate

    def _action_args(self, action: str, type: Any) -> tuple[str, type[Action] | None]:
        self.host.check_open()
        check_name(action, "action")
        return action_type(type)

    # -- sending goals -------------------------------------------------------------------------

    async def send_goal(
        self,
        action: str,
        type: str | type[Action],
        goal: Mapping[str, Any] | Message | None,
        *,
        feedback: bool,
        on_feedback: FeedbackCallback | None,
        buffer_size: int,
    ) -> GoalHandle:
        """Send a goal (see ``RosBase.send_goal``)."""
        host = self.host
        type_name, cls = self._action_args(action, type)
        what = f"goal to {action}"
        goal_cls = _part(cls, "Goal")
        wire = to_wire({} if goal is None else goal, f"{type_name}_Goal", goal_cls, what)
        check_cls = goal_cls
        if goal_cls is None and host.validate:
            check_cls = _part(_action_class(type_name), "Goal")
            check_dict(wire, check_cls, what)
        if goal is not None and wire is goal:
            host.completeness.check(wire, check_cls, what)
        if not host.transport.connected:
            await host.wait_connected(DEFAULT_CALL_TIMEOUT)
        id = host.new_id("send_action_goal", action)
        handle = GoalHandle(self, action, type_name, cls, id, buffer_size=buffer_size,
                            on_feedback=on_feedback)
        self.goals[id] = handle
        # Status errors naming the goal fail it; nobody awaits a verdict on it.
        host.track(id, Tracked(action, handle=handle, awaited=True, confirm=handle.confirmed))
        host.send(ops.SendActionGoal(action=action, action_type=type_name, args=wire, id=id,
                                     feedback=feedback))
        await host.flush()
        return handle

    def goal_ended(self, goal: GoalHandle) -> None:
        self.goals.pop(goal.id, None)
        host = self.host
        if goal.error is None or isinstance(goal.error, ConnectionClosed):
            host.untrack(goal.id)
            return
        # A failed goal's status error may come after its result: keep recognising its id.
        self._failed_goals.append(goal.id)
        while len(self._failed_goals) > _RECENT_FAILED:
            host.untrack(self._failed_goals.popleft())

    def _on_feedback(self, op: ops.ActionFeedback) -> None:
        goal = self.goals.get(str(op.id))
        if goal is not None:
            goal.feedback_arrived(op.values)

    def _on_result(self, op: ops.ActionResultOp) -> None:
        goal = self.goals.get(str(op.id))
        if goal is not None:
            goal.result_arrived(op)
        else:
            log.debug("action_result for an unknown goal %r", op.id)

    # -- serving actions -----------------------------------------------------------------------

    def advertise(
        self, action: str, type: str | type[Action], handler: ActionHandler
    ) -> ActionServer:
        """A new served action (see ``RosBase.advertise_action``)."""
        host = self.host
        type_name, cls = self._action_args(action, type)
        if action in self.servers:
            raise UsageError(f"advertise_action {action}: already served by this client")
        server = ActionServer(self, action, type_name, cls, handler,
                              id=host.new_id("advertise_action", action))
        self.servers[action] = server
        host.request(Tracked(action, handle=server, forget=lambda: self._forget(server)),
                     server.request_op())
        return server

    def _forget(self, server: ActionServer) -> None:
        if self.servers.get(server.action) is server:
            del self.servers[server.action]

    def forget_action(self, server: ActionServer) -> None:
        self._forget(server)
        self.host.untrack(server.id)
        self.host.send(ops.UnadvertiseAction(server.action, id=server.id))

    def _serve_goal(self, op: ops.SendActionGoal) -> None:
        server = self.servers.get(op.action)
        if server is None or op.id is None:
            if op.id is not None:
                self.host.send(ops.ActionResultOp(id=op.id, action=op.action, result=False,
                                                values=f"{op.action} is not served here",
                                                status=int(GoalStatus.ABORTED)))
            return
        ctx = GoalContext(server, str(op.id), asyncio.get_running_loop())
        task = self.host.spawn(server.run_goal(ctx, op.args))
        self.served_goals[ctx.id] = (ctx, task)

    def _on_cancel_goal(self, op: ops.CancelActionGoal) -> None:
        entry = self.served_goals.get(str(op.id))
        if entry is not None:
            entry[0].request_cancel()

    # -- the handles' hooks --------------------------------------------------------------------

    def send(self, op: ops.Op) -> None:
        self.host.send(op)

    async def flush(self) -> None:
        await self.host.flush()

    async def settle(self, handle: Any) -> None:
        await self.host.settle(handle)

    def spawn(self, coro: Coroutine[Any, Any, None]) -> None:
        self.host.spawn(coro)

    def served_goal_done(self, ctx: GoalContext, op: ops.ActionResultOp | None) -> None:
        """A served goal's handler returned: send its result (None: the goal was lost).

        A result that cannot be encoded aborts the goal with the reason.
        """
        self.served_goals.pop(ctx.id, None)
        if op is None:
            return
        self.host.send_or(op, lambda why: ops.ActionResultOp(
            id=op.id, action=op.action, result=False, values=why,
            status=int(GoalStatus.ABORTED)))

    # -- the connection ------------------------------------------------------------------------

    def _restore(self) -> None:
        for server in self.servers.values():
            server.error = None
            self.host.send(server.request_op())

    def _drop(self, error: ConnectionClosed) -> None:
        goals, self.goals = self.goals, {}
        for goal in goals.values():
            if isinstance(error, Disconnected):
                goal.fail(Disconnected(f"{error} while goal {goal.id} to {goal.action} "
                                        "was in flight"))
            else:
                goal.fail(error)
        served, self.served_goals = self.served_goals, {}
        for ctx, task in served.values():
            ctx.lost = True
            ctx.request_cancel()
            if not task.done():
                with contextlib.suppress(RuntimeError):
                    task.cancel()
        if self.host.state is ConnectionState.CLOSED:  # for good: no more goals come
            for server in self.servers.values():
                server.stop_threads()
