"""The front's part of actions: :class:`ActionsMixin`, which :class:`~roslibpy_lite.ros.RosFront`
inherits (``send_goal``, ``advertise_action``, and the ops they send and receive).

The handles and the rules are in :mod:`roslibpy_lite.actions`.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import logging
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, cast

from msgs.runtime import Action, Message

from . import ops
from .actions import (
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
from .api import DEFAULT_CALL_TIMEOUT, ConnectionState
from .exceptions import ConnectionClosed, Disconnected, ProtocolError, UsageError
from .messages import check_dict, check_name, to_wire

if TYPE_CHECKING:
    from .ros import RosFront

__all__ = ["ActionsMixin"]

log = logging.getLogger("roslibpy_lite.client")

_RECENT_FAILED = 64  # failed goals whose late status errors are still recognised


class ActionsMixin:
    """The action part of :class:`~roslibpy_lite.ros.RosFront` (it inherits this)."""

    _goals: dict[str, GoalHandle]
    _action_servers: dict[str, ActionServer]
    _served_goals: dict[str, tuple[GoalContext, asyncio.Task[None]]]
    _failed_goals: collections.deque[str]

    @property
    def _me(self) -> RosFront:
        return cast("RosFront", self)

    def _init_actions(self) -> None:
        """Set up the action state and hook it into the front (called by its ``__init__``)."""
        me = self._me
        self._goals = {}
        self._action_servers = {}
        self._served_goals = {}
        self._failed_goals = collections.deque()
        me._routes[ops.ActionFeedback] = self._on_action_feedback
        me._routes[ops.ActionResult] = self._on_action_result
        me._routes[ops.SendActionGoal] = self._serve_goal
        me._routes[ops.CancelActionGoal] = self._on_cancel_goal
        me._restorers.append(self._restore_actions)
        me._on_drop.append(self._drop_actions)

    def _action_args(self, action: str, type: Any) -> tuple[str, type[Action] | None]:
        self._me._check_open()
        check_name(action, "action")
        return action_type(type)

    # -- sending goals --

    async def send_goal(
        self,
        action: str,
        type: str | type[Action],
        goal: Mapping[str, Any] | Message | None = None,
        *,
        feedback: bool = True,
        on_feedback: FeedbackCallback | None = None,
        buffer_size: int = 100,
    ) -> GoalHandle:
        """Send a goal to the action server of ``action``; returns its :class:`GoalHandle`.

        ``type`` is an action type string (``pkg/action/Name`` or ``pkg/Name``)
        or a msgs action class; ``goal`` a dict or its ``Goal`` instance
        (checked here against the type). ``feedback``: ask for feedback
        (iterate the handle, or pass ``on_feedback``, sync or async);
        ``buffer_size``: feedback kept for iteration (the oldest is dropped).
        Waits for the connection when it is down (at most 10 s).

        Raises:
            UsageError / InvalidMessageError: a bad name, type or goal.
            RosTimeoutError: the connection did not come back in time.
            ConnectionClosed: the client is closed.
        """
        me = self._me
        type_name, cls = self._action_args(action, type)
        what = f"goal to {action}"
        goal_cls = _part(cls, "Goal")
        wire = to_wire({} if goal is None else goal, f"{type_name}_Goal", goal_cls, what)
        if goal_cls is None and me.validate:
            check_dict(wire, _part(_action_class(type_name), "Goal"), what)
        if not me._transport.connected:
            await me._hub.wait_connected(DEFAULT_CALL_TIMEOUT)
        id = me._new_id("send_action_goal", action)
        handle = GoalHandle(me, action, type_name, cls, id, buffer_size=buffer_size,
                            on_feedback=on_feedback)
        self._goals[id] = handle
        me._requests[id] = handle  # status errors naming the goal fail it
        me._awaited.add(id)
        me._send(ops.SendActionGoal(action=action, action_type=type_name, args=wire, id=id,
                                    feedback=feedback))
        await me._flush()
        return handle

    def _goal_ended(self, goal: GoalHandle) -> None:
        self._goals.pop(goal.id, None)
        me = self._me
        if goal.error is None or isinstance(goal.error, ConnectionClosed):
            me._requests.pop(goal.id, None)
            me._awaited.discard(goal.id)
            return
        # A failed goal's status error may come after its result: keep recognising its id.
        self._failed_goals.append(goal.id)
        while len(self._failed_goals) > _RECENT_FAILED:
            old = self._failed_goals.popleft()
            me._requests.pop(old, None)
            me._awaited.discard(old)

    def _on_action_feedback(self, op: ops.ActionFeedback) -> None:
        goal = self._goals.get(str(op.id))
        if goal is not None:
            goal._feedback(op.values)

    def _on_action_result(self, op: ops.ActionResult) -> None:
        goal = self._goals.get(str(op.id))
        if goal is not None:
            goal._result(op)
        else:
            log.debug("action_result for an unknown goal %r", op.id)

    # -- serving actions --

    def advertise_action(
        self, action: str, type: str | type[Action], handler: ActionHandler
    ) -> ActionServer:
        """Serve ``action`` to ROS callers with ``handler`` (module doc); ``await`` it.

        Raises:
            UsageError: a bad name or type, or the action is already served here.
            StatusError: the bridge refused (raised at ``await``, which waits for the
                verdict of a confirming bridge; else see
                :meth:`~roslibpy_lite.ros.RosFront.on_error`).
            ConnectionClosed: the client is closed.
        """
        me = self._me
        type_name, cls = self._action_args(action, type)
        if action in self._action_servers:
            raise UsageError(f"advertise_action {action}: already served by this client")
        server = ActionServer(me, action, type_name, cls, handler,
                              id=me._new_id("advertise_action", action))
        self._action_servers[action] = server
        me._request(server, server.request_op())
        return server

    def _drop_action_server(self, server: ActionServer) -> None:
        if self._action_servers.get(server.action) is server:
            del self._action_servers[server.action]
        self._me._requests.pop(server.id, None)

    def _serve_goal(self, op: ops.SendActionGoal) -> None:
        me = self._me
        server = self._action_servers.get(op.action)
        if server is None or op.id is None:
            if op.id is not None:
                me._send(ops.ActionResult(id=op.id, action=op.action, result=False,
                                          values=f"{op.action} is not served here",
                                          status=int(GoalStatus.ABORTED)))
            return
        ctx = GoalContext(server, str(op.id), asyncio.get_running_loop())
        task = self._spawn(server._run(ctx, op.args))
        self._served_goals[ctx.id] = (ctx, task)

    def _on_cancel_goal(self, op: ops.CancelActionGoal) -> None:
        entry = self._served_goals.get(str(op.id))
        if entry is not None:
            entry[0]._request_cancel()

    def _spawn(self, coro: Any) -> asyncio.Task[None]:
        task: asyncio.Task[None] = asyncio.get_running_loop().create_task(coro)
        tasks = self._me._handler_tasks
        tasks.add(task)
        task.add_done_callback(tasks.discard)
        return task

    def _send_checked(self, op: ops.ActionResult) -> None:
        """Send a served goal's result; one that cannot be encoded aborts it with the reason."""
        me = self._me
        t = me._transport
        if not t.connected:
            return
        try:
            frame = t.encode(op)
        except ProtocolError as exc:
            frame = t.encode(ops.ActionResult(id=op.id, action=op.action, result=False,
                                              values=exc.message,
                                              status=int(GoalStatus.ABORTED)))
        t.write(frame)

    # -- the connection --

    def _restore_actions(self) -> None:
        me = self._me
        for server in self._action_servers.values():
            server.error = None
            me._send(server.request_op())

    def _drop_actions(self, error: ConnectionClosed) -> None:
        goals, self._goals = self._goals, {}
        for goal in goals.values():
            if isinstance(error, Disconnected):
                goal._fail(Disconnected(f"{error} while goal {goal.id} to {goal.action} "
                                        "was in flight"))
            else:
                goal._fail(error)
        served, self._served_goals = self._served_goals, {}
        for ctx, task in served.values():
            ctx.lost = True
            ctx._request_cancel()
            if not task.done():
                with contextlib.suppress(RuntimeError):
                    task.cancel()
        if self._me.state is ConnectionState.CLOSED:  # for good: no more goals come
            for server in self._action_servers.values():
                server._stop_threads()

