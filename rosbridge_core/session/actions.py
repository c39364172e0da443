"""What one session does with actions: goals it sends, and actions it serves.

A :class:`SessionActions` belongs to one :class:`~rosbridge_core.session.Session`
(``session.actions``), which hands it the action ops listed in
:attr:`SessionActions.OPS` and calls :meth:`SessionActions.close` when the client
goes away. The ROS side is the session's :class:`~rosbridge_core.graph.Graph` (on
rclpy: :mod:`bridge_server.rclpy_graph.actions`).

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
import json
import logging
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, ClassVar

from rosbridge_core.graph import ACTIVE, CANCEL_ANSWERS, Status
from rosbridge_core.interfaces import BridgeError, ConversionError, args_mapping, canonical_name
from rosbridge_core.protocol import ops
from rosbridge_core.security.names import full_name
from rosbridge_core.session.limits import over_cap

if TYPE_CHECKING:
    from rosbridge_core.graph import ActionClient, Converter, SentGoal, ServedAction, ServedGoal
    from rosbridge_core.security import Gate
    from rosbridge_core.session.host import Host

__all__ = ["ActionClients", "SessionActions"]

log = logging.getLogger("bridge_server.session.actions")

ACTION_LINGER = 1.0
"""Seconds an unadvertised action server stays in ROS, so callers fetch the aborted results."""

CLIENT_IDLE = 30.0
"""Seconds an action client nobody uses is kept (it stays matched for the next goal)."""

_GOAL_SUFFIX = "/_action/send_goal"
_CANCEL_SUFFIX = "/_action/cancel_goal"
_OUTCOMES: dict[int, str] = {Status.SUCCEEDED: "succeeded", Status.CANCELED: "canceled",
             Status.ABORTED: "aborted"}


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

    def get(self, session: Host, name: str, action_cls: type[Any]) -> ActionClient:
        """The shared client for ``name`` of ``action_cls`` (created on first use)."""
        key = (name, action_cls)
        client = self.clients.get(key)
        if client is None:
            client = self.clients[key] = session.graph.action_client(name, action_cls)
        self.touch(session, client)
        return client

    def touch(self, session: Host, client: ActionClient) -> None:
        """``client`` is in use now."""
        loop = session.loop
        self._used[(client.name, client.action_cls)] = loop.time()
        if self._sweeper is None:
            self._sweeper = loop.call_later(CLIENT_IDLE, self._sweep, session)

    def _sweep(self, session: Host) -> None:
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


class _Goal:
    """A goal this client sent, from ``send_action_goal`` to ``action_result``."""

    def __init__(self, owner: SessionActions, op: ops.SendActionGoal, id: ops.Id,
                 name: str, type_name: str) -> None:
        self.owner = owner
        self.id = id
        self.name = name
        self.wire = op.action
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
            if status == Status.CANCELED:
                self.owner.fail(self, "the goal was canceled before it was sent", status)
            else:
                self.owner.fail(self, "the action server did not answer the goal")
            return
        self.owner.finish(self, _OUTCOMES.get(status, "failed"))
        self.owner.emit(self, "action_result", result, self.sent.shared.result_conv, status)


class ClientAction:
    """An action this client serves, and the ROS goals it is carrying out."""

    def __init__(self, name: str, wire: str, type_name: str) -> None:
        self.name = name
        self.wire = wire
        self.type_name = type_name
        self.ros: ServedAction | None = None
        self.goals: dict[str, tuple[ServedGoal, asyncio.TimerHandle | None]] = {}
        self.ids: dict[int, str] = {}  # id(ServedGoal) -> goal id, for ROS cancel requests


class SessionActions:
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
        return over_cap(self.goals, full_name(op.action), self.session.limits.max_goals,
                        "goals in flight")

    def serve_limit(self, op: ops.AdvertiseAction) -> str | None:
        """Why serving one more action (each an rclpy action server) would pass the limits."""
        return over_cap(self.served, full_name(op.action), self.session.limits.max_services,
                        "served actions")

    def __init__(self, session: Host) -> None:
        self.session = session
        self.goals: dict[str, _Goal] = {}
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

    # -- sending goals -------------------------------------------------------------------------

    def send_goal(self, op: ops.SendActionGoal) -> None:
        """Start a goal: convert it, then wait for a server and send it (a task)."""
        name = full_name(op.action)
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
        goal = _Goal(self, op, id, name, type_name)
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
                             status=Status.ABORTED)
        )

    async def _start(self, goal: _Goal, action_cls: type[Any], goal_msg: Any) -> None:
        try:
            client = await self._server_for(goal, action_cls)
        except _Failed as exc:
            self.fail(goal, str(exc))
            self.session.error(f"send_action_goal: {exc}", goal.id)
            return
        finally:
            goal.task = None
        if goal.cancel_wanted:
            self.fail(goal, "the goal was canceled before it was sent", Status.CANCELED)
            return
        goal.sent = client.send(goal_msg, goal, goal.feedback)
        wait = self.session.config.call_timeout
        goal.answer_timer = self.session.loop.call_later(wait, goal.no_answer, wait)

    async def _server_for(self, goal: _Goal, action_cls: type[Any]) -> ActionClient:
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
            types = session.graph.server_types(name + _GOAL_SUFFIX)
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
                f"cancel_action_goal: no goal {op.id!r} of {full_name(op.action)} is in flight "
                "on this connection",
                op.id,
            )
            return
        goal.cancel_wanted = True
        if goal.sent is not None:
            goal.sent.cancel()
        elif goal.task is not None:  # still waiting for an action server
            goal.task.cancel()
            self.fail(goal, "the goal was canceled before it was sent", Status.CANCELED)

    def _expired(self, goal: _Goal, timeout: float) -> None:
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

    def finish(self, goal: _Goal, outcome: str) -> None:
        """Forget a goal (its result was sent, or is about to be) and count its ``outcome``."""
        if self.goals.get(str(goal.id)) is goal:
            del self.goals[str(goal.id)]
            seconds = self.session.loop.time() - goal.t0
            self.session.shared.metrics.action_goal(goal.name, outcome, seconds)
        if goal.timer is not None:
            goal.timer.cancel()
            goal.timer = None
        goal._answered()

    def fail(self, goal: _Goal, why: str, status: int = Status.ABORTED) -> None:
        """End a goal that did not run to a result: ``result: false`` with a text."""
        if self.goals.get(str(goal.id)) is not goal:
            return
        self.finish(goal, "canceled" if status == Status.CANCELED else "failed")
        log.info("session %d: goal %s on %s failed: %s", self.session.sid, goal.id, goal.name, why)
        self.session.send_op(
            ops.ActionResultOp(id=goal.id, action=goal.wire, values=f"{goal.name}: {why}",
                             result=False, status=status)
        )

    def emit(self, goal: _Goal, op: str, msg: Any, conv: Converter,
             status: int | None = None) -> None:
        """Send ``action_feedback`` or ``action_result`` with ``msg`` as values (JSON or CBOR)."""
        session = self.session
        if goal.cbor:
            import cbor2  # only for a client that asked for CBOR (MockRos may run without it)

            obj: dict[str, Any] = {"op": op, "id": goal.id, "action": goal.wire,
                                   "values": conv.to_cbor_obj(msg)}
            if status is not None:  # a goal that ran to a final status: result true, as
                obj["status"] = status  # rosbridge sends it (false: it never ran, see fail)
                obj["result"] = status in _RAN
            session.send_text(cbor2.dumps(obj))
            return
        head = json.dumps({"op": op, "id": goal.id, "action": goal.wire})[:-1]
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

    # -- serving actions -----------------------------------------------------------------------

    def advertise(self, op: ops.AdvertiseAction) -> None:
        """Serve an action from this client (an rclpy action server in the bridge)."""
        session = self.session
        name = full_name(op.action)
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
        goal_service = name + _GOAL_SUFFIX

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
            goal.finish(Status.ABORTED)
            return
        gid = f"action_goal:{served.wire}:{next(self._goal_ids)}"
        try:
            args = goal.served.goal_conv.to_obj(goal.request)
        except Exception:
            log.exception("cannot convert a goal of %s", served.name)
            goal.finish(Status.ABORTED)
            return
        timer = None
        timeout = session.config.goal_timeout
        if timeout > 0:
            timer = session.loop.call_later(timeout, self._served_expired, served, gid, timeout)
        served.goals[gid] = (goal, timer)
        served.ids[id(goal)] = gid
        session.send_op(
            ops.SendActionGoal(action=served.wire, action_type=served.type_name, args=args,
                               id=gid, feedback=True)
        )

    def _on_ros_cancel(self, served: ClientAction, goal: ServedGoal) -> None:
        gid = served.ids.get(id(goal))
        if gid is not None and gid in served.goals:
            self.session.send_op(ops.CancelActionGoal(id=gid, action=served.wire))

    def _served_expired(self, served: ClientAction, gid: str, timeout: float) -> None:
        entry = self._pop_goal(served, gid)
        if entry is None:
            return
        log.error("session %d: goal %s not finished within %s s; aborting it",
                  self.session.sid, gid, timeout)
        entry.finish(Status.ABORTED)
        self.session.send_op(ops.CancelActionGoal(id=gid, action=served.wire))
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
        served = self.served.get(full_name(op.action))
        if served is not None and gid in served.goals:
            return served, gid
        for s in self.served.values():
            if gid in s.goals:
                return s, gid
        self.session.error(
            f"{op.OP}: no goal {op.id!r} of {full_name(op.action)} is waiting on this client", op.id
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
            status = Status.SUCCEEDED if op.result else Status.ABORTED
        elif status in ACTIVE or status not in (Status.SUCCEEDED, Status.CANCELED,
                                                Status.ABORTED):
            self.session.error(
                f"action_result for {served.name}: status {status} is not a final status "
                "(4 succeeded, 5 canceled, 6 aborted); the goal was aborted",
                op.id,
            )
            status = Status.ABORTED
        elif not op.result and status == Status.SUCCEEDED:
            status = Status.ABORTED
        result = None
        if isinstance(op.values, Mapping):
            try:
                result = goal.served.result_conv.from_obj(op.values, "values")
            except ConversionError as exc:
                self.session.error(
                    f"action_result for {served.name}: {exc}; the goal was aborted", op.id
                )
                status, result = Status.ABORTED, None
        elif op.values is not None and status != Status.SUCCEEDED:
            log.info("session %d: goal %s ended (status %d): %s", self.session.sid, gid, status,
                     op.values)
        goal.finish(status, result)

    def unadvertise(self, op: ops.UnadvertiseAction) -> None:
        """Stop serving an action; its goals are aborted at once."""
        self._owners.unadvertise(self, op, full_name(op.action))

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
                goal.finish(Status.ABORTED)
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


_RAN = (Status.SUCCEEDED, Status.CANCELED, Status.ABORTED)
"""Final statuses of a goal that ran: its action_result says result true, as rosbridge does."""
