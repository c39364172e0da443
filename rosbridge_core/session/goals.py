"""Goals one session sends: ``send_action_goal`` and ``cancel_action_goal``
(:class:`GoalSending`, the sending half of
:class:`~rosbridge_core.session.actions.SessionActions`), the goals in flight
(:class:`ClientGoal`) and the bridge's shared action clients (:class:`ActionClients`).

Sending goals
-------------
``send_action_goal`` (``args`` an object, or a list zipped onto the goal's
fields) converts the goal, waits for an action server (at most
``call_timeout`` s; twice ``discovery_wait`` s if no server is matched and the ROS
graph does not list the action at all: one started just before can take ~3 s to
appear on a loaded machine, as for typed service calls) and sends it. A newly
matched server is first probed until it answers (see
:meth:`~rosbridge_core.graph.ActionClient.ready`), so that the goal's
answer cannot be lost to discovery still under way. With ``feedback: true`` each feedback goes back
as ``action_feedback`` {id, action, values}. The end is one ``action_result``
{id, action, values, status, result}: ``status`` is the GoalStatus number,
``result`` is true only for SUCCEEDED, ``values`` the action's result. A goal
that never ran (no server, rejected, bad goal, timed out, canceled before it
left the bridge) ends with ``result: false``, ``values`` a text saying why and
status ABORTED (6), or CANCELED (5) for the last case. Bad input also gets a
``status`` error. ``compression: cbor`` sends feedback and result as CBOR
binary frames; ``fragment_size`` splits JSON ones.
A goal the server neither accepts nor rejects within ``call_timeout`` s (a
lost request: rclpy servers keep only 10 requests by default) fails too.
``cancel_action_goal`` with the goal's id cancels it, before or after the
server accepted it; the result (usually CANCELED) follows. A refused cancel
is reported as a ``status`` warning. The id names one of this connection's own
goals: the op cannot reach another client's. When the client disconnects, its goals
are canceled on the ROS side. ``goal_timeout`` (s, 0 = none) cancels goals
that run longer, and fails them with a text.

The action's services called as plain services
-----------------------------------------------
``call_service`` to ``<action>/_action/cancel_goal`` (which ``send_action_goal``
on the action allows, see :func:`~rosbridge_core.security.permissions.hidden_requirement`)
cancels only goals this connection sent with ``send_action_goal``, unless the
client's role has ``cancel_any_goal`` on the action. A cancel of
another's goal id, of a zero id (every goal) or with a stamp (every goal
accepted before it) is refused with a text that says so; it is not narrowed,
since the caller would be told of fewer goals canceling than it asked for.
Without an auth file there are no roles, and no such limit.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import logging
from typing import TYPE_CHECKING, Any

from rosbridge_core.graph import CANCEL_ANSWERS
from rosbridge_core.interfaces import BridgeError, ConversionError, args_mapping, canonical_name
from rosbridge_core.protocol import ops
from rosbridge_core.protocol.goal_status import GoalStatus
from rosbridge_core.protocol.names import absolute_name

if TYPE_CHECKING:
    from rosbridge_core.graph import ActionClient, Converter, SentGoal, ServedAction
    from rosbridge_core.session.host import SessionView
    from rosbridge_core.session.ownership import Ownership

__all__ = ["CLIENT_IDLE", "GOAL_SUFFIX", "ActionClients", "ClientGoal", "GoalSending"]

log = logging.getLogger("bridge_server.session.actions")

CLIENT_IDLE = 30.0
"""Seconds an action client nobody uses is kept (it stays matched for the next goal)."""

GOAL_SUFFIX = "/_action/send_goal"
"""An action's goal service, after its name."""
_CANCEL_SUFFIX = "/_action/cancel_goal"
_OUTCOMES: dict[int, str] = {GoalStatus.SUCCEEDED: "succeeded", GoalStatus.CANCELED: "canceled",
             GoalStatus.ABORTED: "aborted"}


class ActionClients:
    """The bridge's shared rclpy action clients, one per (action, type).

    A client no goal has used for :data:`CLIENT_IDLE` seconds is destroyed: each one
    adds entities to every wait set of the executor.
    """

    def __init__(self) -> None:
        self.clients: dict[tuple[str, type[Any]], ActionClient] = {}
        self.lingering: dict[str, ServedAction] = {}  # unadvertised, still answering callers
        self._used: dict[tuple[str, type[Any]], float] = {}
        self._sweeper: asyncio.TimerHandle | None = None

    def get(self, session: SessionView, name: str, action_cls: type[Any]) -> ActionClient:
        """The shared client for ``name`` of ``action_cls`` (created on first use)."""
        key = (name, action_cls)
        client = self.clients.get(key)
        if client is None:
            client = self.clients[key] = session.graph.action_client(name, action_cls)
        self.touch(session, client)
        return client

    def touch(self, session: SessionView, client: ActionClient) -> None:
        """``client`` is in use now."""
        loop = session.loop
        self._used[(client.name, client.action_cls)] = loop.time()
        if self._sweeper is None:
            self._sweeper = loop.call_later(CLIENT_IDLE, self._sweep, session)

    def _sweep(self, session: SessionView) -> None:
        self._sweeper = None
        now = session.loop.time()
        busy = {id(g.sent.shared) for s in session.shared.sessions
                for g in s.actions.goals.values() if g.sent is not None}
        for key, used in list(self._used.items()):
            client = self.clients.get(key)
            if client is None or (now - used >= CLIENT_IDLE and id(client) not in busy):
                self._used.pop(key, None)
                if client is not None:
                    del self.clients[key]
                    client.destroy()
        if self._used:
            self._sweeper = session.loop.call_later(CLIENT_IDLE, self._sweep, session)


class _Failed(Exception):
    """A goal cannot be sent; the text goes back as the ``action_result`` values."""

class ClientGoal:
    """A goal this client sent, from ``send_action_goal`` to ``action_result``."""

    def __init__(self, owner: GoalSending, op: ops.SendActionGoal, id: ops.Id,
                 name: str, type_name: str) -> None:
        self.owner = owner
        self.id = id
        self.name = name
        self.spelled = op.action
        self.type_name = type_name
        self.feedback = bool(op.feedback)
        self.cbor = op.compression == "cbor"
        self.fragment_size = op.fragment_size
        self.sent: SentGoal | None = None
        self.task: asyncio.Task[None] | None = None
        self.timer: asyncio.TimerHandle | None = None
        self.answer_timer: asyncio.TimerHandle | None = None
        self.cancel_wanted = False
        self.t0 = owner.session.loop.time()

    # -- what the ROS side reports (loop thread) -----------------------------------------------

    def _live(self) -> bool:
        return self.owner.goals.get(str(self.id)) is self

    def on_accepted(self) -> None:
        self._answered()
        log.debug("goal %s on %s accepted", self.id, self.name)
        session = self.owner.session
        if session.acks and self._live():  # the client asked for verdicts (ACKS_HEADER)
            session.send_op(ops.Status(level="info", msg=f"ok: send_action_goal {self.name} "
                                       "accepted by the action server", id=self.id))

    def on_rejected(self) -> None:
        self._answered()
        if self._live():
            self.owner.fail(self, "the action server rejected the goal")

    def _answered(self) -> None:
        if self.answer_timer is not None:
            self.answer_timer.cancel()
            self.answer_timer = None

    def no_answer(self, timeout: float) -> None:
        """The action server did not accept or reject the goal in time (its request was lost)."""
        self.answer_timer = None
        if self._live():
            if self.sent is not None:
                self.sent.cancel()  # in case it is accepted after all
            self.owner.fail(
                self, f"the action server did not answer the goal request within {timeout} s"
            )

    def on_feedback(self, feedback: Any) -> None:
        if self._live() and self.sent is not None:
            conv = self.sent.shared.feedback_conv
            self.owner.emit(self, "action_feedback", feedback, conv)

    def on_cancel_answer(self, code: int) -> None:
        if self._live() and code in CANCEL_ANSWERS:
            self.owner.session.status(
                "warning",
                f"cancel_action_goal: goal {self.id!r} of {self.name} was not canceled: "
                f"{CANCEL_ANSWERS[code]}",
                self.id,
            )

    def on_failed(self, why: str) -> None:
        self._answered()
        if self._live():
            self.owner.fail(self, why)

    def on_result(self, status: int, result: Any) -> None:
        if not self._live():
            return
        if result is None or self.sent is None:
            if status == GoalStatus.CANCELED:
                self.owner.fail(self, "the goal was canceled before it was sent", status)
            else:
                self.owner.fail(self, "the action server did not answer the goal")
            return
        self.owner.finish(self, _OUTCOMES.get(status, "failed"))
        self.owner.emit(self, "action_result", result, self.sent.shared.result_conv, status)


class GoalSending:
    """The goals one client sends (the sending half of
    :class:`~rosbridge_core.session.actions.SessionActions`)."""

    session: SessionView
    goals: dict[str, ClientGoal]
    _owners: Ownership[Any]
    _goal_ids: itertools.count[int]

    # -- sending goals -------------------------------------------------------------------------

    def send_goal(self, op: ops.SendActionGoal) -> None:
        """Start a goal: convert it, then wait for a server and send it (a task)."""
        name = absolute_name(op.action)
        id: ops.Id = op.id if op.id is not None else (
            f"send_action_goal:{op.action}:{next(self._goal_ids)}"
        )
        if str(id) in self.goals:
            self.session.error(f"send_action_goal: goal {id!r} is already in flight", id)
            return
        try:
            action_cls = self.session.graph.resolve_action(op.action_type)
            type_name = canonical_name(op.action_type, "action")
        except BridgeError as exc:
            self._refuse(op, id, f"send_action_goal to {name}: {exc}")
            return
        conv = self.session.graph.converter(action_cls.Goal)
        try:
            goal_msg = conv.from_obj(args_mapping(op.args, conv.fields, "goal"), "args")
        except ConversionError as exc:
            self._refuse(op, id, f"send_action_goal to {name} ({type_name}): {exc}")
            return
        goal = ClientGoal(self, op, id, name, type_name)
        self.goals[str(id)] = goal
        timeout = self.session.config.goal_timeout
        if timeout > 0:
            goal.timer = self.session.loop.call_later(timeout, self._expired, goal, timeout)
        goal.task = self.session.loop.create_task(self._start(goal, action_cls, goal_msg))

    def _refuse(self, op: ops.SendActionGoal, id: ops.Id, text: str) -> None:
        """Bad input: a status error, and the failed result stock clients wait for."""
        self.session.error(text, id)
        self.session.send_op(
            ops.ActionResultOp(id=id, action=op.action, values=text, result=False,
                             status=GoalStatus.ABORTED)
        )

    async def _start(self, goal: ClientGoal, action_cls: type[Any], goal_msg: Any) -> None:
        try:
            client = await self._server_for(goal, action_cls)
        except _Failed as exc:
            self.fail(goal, str(exc))
            self.session.error(f"send_action_goal: {exc}", goal.id)
            return
        finally:
            goal.task = None
        if goal.cancel_wanted:
            self.fail(goal, "the goal was canceled before it was sent", GoalStatus.CANCELED)
            return
        goal.sent = client.send(goal_msg, goal, goal.feedback)
        wait = self.session.config.call_timeout
        goal.answer_timer = self.session.loop.call_later(wait, goal.no_answer, wait)

    async def _server_for(self, goal: ClientGoal, action_cls: type[Any]) -> ActionClient:
        session = self.session
        loop = session.loop
        name = goal.name
        wanted = goal.type_name + "_SendGoal"
        config = session.config
        clients = session.shared.action_clients
        deadline = loop.time() + config.call_timeout
        listed_by = loop.time() + min(2 * config.discovery_wait, config.call_timeout)
        delay = 0.002
        while True:
            client = clients.clients.get((name, action_cls))
            if client is not None and client.ready():
                clients.touch(session, client)
                return client
            types = session.graph.server_types(name + GOAL_SUFFIX)
            owner = self._owners.get(name)
            if not types and owner is not None and name in owner.served:
                # served by a client of this bridge: it exists even while the graph lags
                types = [owner.served[name].type_name + "_SendGoal"]
            if types and wanted not in types:
                raise _Failed(
                    f"action {name} has type {types[0].removesuffix('_SendGoal')}, "
                    f"not {goal.type_name}"
                )
            if types:
                client = clients.get(session, name, action_cls)
                if client.ready():
                    return client
            now = loop.time()
            # A matched server exists, even while the graph does not list it yet.
            matched = client is not None and client.matched()
            if not types and not matched and now >= listed_by:
                raise _Failed(f"action {name} does not exist (no action server in the ROS graph)")
            if now >= deadline:
                raise _Failed(
                    f"action {name} has no action server ready within {config.call_timeout} s"
                )
            await asyncio.sleep(delay)
            delay = min(delay * 2, 0.05)

    def cancel_goal(self, op: ops.CancelActionGoal) -> None:
        """Cancel a goal this client sent (its result follows)."""
        goal = self.goals.get(str(op.id))
        if goal is None:
            self.session.error(
                f"cancel_action_goal: no goal {op.id!r} of {absolute_name(op.action)} is in flight "
                "on this connection",
                op.id,
            )
            return
        goal.cancel_wanted = True
        if goal.sent is not None:
            goal.sent.cancel()
        elif goal.task is not None:  # still waiting for an action server
            goal.task.cancel()
            self.fail(goal, "the goal was canceled before it was sent", GoalStatus.CANCELED)

    def _expired(self, goal: ClientGoal, timeout: float) -> None:
        goal.timer = None
        if self.goals.get(str(goal.id)) is not goal:
            return
        if goal.sent is not None:
            goal.sent.cancel()
            self.fail(goal, f"the goal timed out after {timeout} s (canceled on the action "
                      "server)")
            return
        if goal.task is not None:
            goal.task.cancel()
        self.fail(goal, f"the goal timed out after {timeout} s, before an action server was "
                  "ready for it (it was never sent)")

    def finish(self, goal: ClientGoal, outcome: str) -> None:
        """Forget a goal (its result was sent, or is about to be) and count its ``outcome``."""
        if self.goals.get(str(goal.id)) is goal:
            del self.goals[str(goal.id)]
            seconds = self.session.loop.time() - goal.t0
            self.session.shared.metrics.action_goal(goal.name, outcome, seconds)
        if goal.timer is not None:
            goal.timer.cancel()
            goal.timer = None
        goal._answered()

    def fail(self, goal: ClientGoal, why: str, status: int = GoalStatus.ABORTED) -> None:
        """End a goal that did not run to a result: ``result: false`` with a text."""
        if self.goals.get(str(goal.id)) is not goal:
            return
        self.finish(goal, "canceled" if status == GoalStatus.CANCELED else "failed")
        log.info("session %d: goal %s on %s failed: %s", self.session.sid, goal.id, goal.name, why)
        self.session.send_op(
            ops.ActionResultOp(id=goal.id, action=goal.spelled, values=f"{goal.name}: {why}",
                             result=False, status=status)
        )

    def emit(self, goal: ClientGoal, op: str, msg: Any, conv: Converter,
             status: int | None = None) -> None:
        """Send ``action_feedback`` or ``action_result`` with ``msg`` as values (JSON or CBOR)."""
        session = self.session
        if goal.cbor:
            import cbor2  # only for a client that asked for CBOR (MockRos may run without it)

            obj: dict[str, Any] = {"op": op, "id": goal.id, "action": goal.spelled,
                                   "values": conv.to_cbor_obj(msg)}
            if status is not None:  # a goal that ran to a final status: result true, as
                obj["status"] = status  # rosbridge sends it (false: it never ran, see fail)
                obj["result"] = status in _RAN
            session.send_text(cbor2.dumps(obj))
            return
        head = json.dumps({"op": op, "id": goal.id, "action": goal.spelled})[:-1]
        tail = "}"
        if status is not None:
            ok = "true" if status in _RAN else "false"
            tail = f',"status":{status},"result":{ok}}}'
        text = f'{head},"values":{conv.to_json(msg)}{tail}'
        session.outbox.send_split(text, goal.fragment_size, None, str(goal.id))

    # -- an action's services, called as plain services (call_service) -----------------------

    def cancel_refusal(self, service: str, request: Any) -> str | None:
        """Why this client may not send ``request`` to ``service`` (``None``: it may).

        Only ``<action>/_action/cancel_goal`` is limited: see the module docstring.
        """
        action = service.removesuffix(_CANCEL_SUFFIX)
        role = self.session.gate.role
        if action == service or role is None or role.allows("cancel_any_goal", action):
            return None
        grant = f"cancel_any_goal on {action} allows it"
        info = getattr(request, "goal_info", None)
        if info is None:
            return "forbidden: the request must be an action_msgs/srv/CancelGoal request"
        uuid = bytes(info.goal_id.uuid)
        if info.stamp.sec or info.stamp.nanosec or not any(uuid):
            return (f"forbidden: role {role.name} may cancel only goals this connection sent, "
                    "and a zero goal id or a stamp cancels other clients' goals too: give "
                    f"one goal's id and a zero stamp ({grant})")
        if any(
            g.name == action and g.sent is not None and g.sent.handle is not None
            and bytes(g.sent.handle.goal_id.uuid) == uuid
            for g in self.goals.values()
        ):
            return None
        return (f"forbidden: role {role.name} may not cancel goal {uuid.hex()} of {action}: "
                f"this connection did not send it ({grant})")


_RAN = (GoalStatus.SUCCEEDED, GoalStatus.CANCELED, GoalStatus.ABORTED)
"""Final statuses of a goal that ran: its action_result says result true, as rosbridge does."""
