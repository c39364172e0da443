"""The bridge's action part, played in memory (for :class:`~.memory.MemoryTransport`).

As the bridge does: a ``send_action_goal`` to an action served here (by
``advertise_action``) reaches the serving handler as a ``send_action_goal``
with an ``action_goal:<action>:<n>`` id; its ``action_feedback`` and
``action_result`` go back to the sender under the sender's id; a sender's
``cancel_action_goal`` reaches the server as a ``cancel_action_goal``. The
bridge's refusals come with its texts: an unknown action type, no action
server ("does not exist"), another type than the served one, a goal that
does not fit the type (a ``status`` error naming the goal, and a failed
``action_result``). A served goal whose server goes away (unadvertised,
dropped) is aborted, and the sender gets the default result, as a ROS action
client would.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

from msgs.runtime import UnknownTypeError, lookup_action

from ..messages import canonical_type
from ..protocol import ops

if TYPE_CHECKING:
    from msgs.runtime import Action


__all__ = ["ACTION_OPS", "MemoryActions"]

ACTION_OPS = (ops.SendActionGoal, ops.CancelActionGoal, ops.ActionFeedback, ops.ActionResultOp,
              ops.AdvertiseAction, ops.UnadvertiseAction)
_SUCCEEDED, _CANCELED, _ABORTED = 4, 5, 6


@dataclass
class _Goal:
    caller_id: ops.Id
    caller_action: str
    served: str
    type_name: str
    feedback: bool


def _name(action: str) -> str:
    return "/" + action.lstrip("/")


class Bridge(Protocol):
    """What the actions' part uses of the in-memory bridge it belongs to
    (:class:`~roslibpy_lite.transports.memory.MemoryTransport`)."""

    validate: bool
    """Whether goals, feedback and results are checked against their types."""

    def to_client(self, op: ops.Op) -> None:
        """Hand ``op`` to the client, as the bridge would send it."""
        ...

    def send_error(self, msg: str, id: ops.Id | None) -> None:
        """Tell the client of an error (a ``status`` op naming ``id``)."""
        ...

    def check(self, wire: Mapping[str, Any], type_name: str, what: str) -> str | None:
        """The bridge's complaint about ``wire`` as a ``type_name``, or None."""
        ...


class MemoryActions:
    """Served actions and goals in flight of one in-memory bridge."""

    def __init__(self, bridge: Bridge) -> None:
        self.bridge = bridge
        self.served: dict[str, tuple[str, str]] = {}
        """Served actions: name → (the name as the client spelled it, type)."""
        self.goals: dict[str, _Goal] = {}
        self._by_caller: dict[str, str] = {}
        self._n = 0

    def handle(self, op: ops.Op) -> None:
        """Carry out one action op."""
        if isinstance(op, ops.SendActionGoal):
            self._send_goal(op)
        elif isinstance(op, ops.CancelActionGoal):
            self._cancel(op)
        elif isinstance(op, ops.ActionFeedback):
            self._feedback(op)
        elif isinstance(op, ops.ActionResultOp):
            self._result(op)
        elif isinstance(op, ops.AdvertiseAction):
            self._advertise(op)
        elif isinstance(op, ops.UnadvertiseAction):
            self._unadvertise(op)

    def drop(self) -> None:
        """The session ended: its served actions and goals go (nobody is told: the link is down)."""
        self.served.clear()
        self.goals.clear()
        self._by_caller.clear()

    def _cls(self, type_name: str) -> type[Action] | None:
        try:
            return lookup_action(type_name)
        except UnknownTypeError:
            return None

    # -- a client sends goals --

    def _refuse(self, op: ops.SendActionGoal, text: str) -> None:
        id = op.id if op.id is not None else ""
        self.bridge.send_error(text, id)
        self._to_caller(id, op.action, text, _ABORTED)

    def _to_caller(self, id: ops.Id, action: str, values: Mapping[str, Any] | str,
                   status: int) -> None:
        # As rosbridge: result true for a goal that ran to a final status (its values),
        # false only for one that never ran (a text saying why).
        ran = not isinstance(values, str) and status in (_SUCCEEDED, _CANCELED, _ABORTED)
        self.bridge.to_client(ops.ActionResultOp(id=id, action=action, values=values,
                                               status=status, result=ran))

    def _send_goal(self, op: ops.SendActionGoal) -> None:
        name = _name(op.action)
        type_name = canonical_type(op.action_type, "action")
        cls = self._cls(type_name)
        if cls is None and self.bridge.validate:
            self._refuse(op, f"send_action_goal to {name}: unknown action type "
                             f"{op.action_type!r} (not installed)")
            return
        args = op.args if isinstance(op.args, Mapping) else {}
        problem = self.bridge.check(args, f"{type_name}_Goal", "args")
        if problem is not None:
            self._refuse(op, f"send_action_goal to {name} ({type_name}): {problem}")
            return
        served = self.served.get(name)
        if served is None:
            text = f"action {name} does not exist (no action server in the ROS graph)"
            self._to_caller(op.id or "", op.action, f"{name}: {text}", _ABORTED)
            self.bridge.send_error(f"send_action_goal: {text}", op.id)
            return
        if served[1] != type_name:
            text = f"action {name} has type {served[1]}, not {type_name}"
            self._to_caller(op.id or "", op.action, f"{name}: {text}", _ABORTED)
            self.bridge.send_error(f"send_action_goal: {text}", op.id)
            return
        self._n += 1
        gid = f"action_goal:{served[0]}:{self._n}"
        self.goals[gid] = _Goal(op.id or "", op.action, name, type_name, bool(op.feedback))
        self._by_caller[str(op.id)] = gid
        self.bridge.to_client(ops.SendActionGoal(action=served[0], action_type=type_name,
                                                 args=dict(args), id=gid, feedback=True))
        # a served action accepts every goal; the caller hears it as from our bridge
        self.bridge.to_client(ops.Status("info", f"ok: send_action_goal {name} accepted by "
                                          "the action server", id=op.id))

    def _cancel(self, op: ops.CancelActionGoal) -> None:
        gid = self._by_caller.get(str(op.id))
        goal = self.goals.get(gid) if gid is not None else None
        if gid is None or goal is None:
            self.bridge.send_error(f"cancel_action_goal: no goal {op.id!r} of {_name(op.action)} "
                               "is in flight on this connection", op.id)
            return
        self.bridge.to_client(ops.CancelActionGoal(id=gid, action=self.served[goal.served][0]))

    # -- a client serves an action --

    def _advertise(self, op: ops.AdvertiseAction) -> None:
        type_name = canonical_type(op.type, "action")
        if self._cls(type_name) is None and self.bridge.validate:
            self.bridge.send_error(f"advertise_action: unknown action type {op.type!r} "
                               "(not installed)", op.id)
            return
        self.served[_name(op.action)] = (op.action, type_name)
        self.bridge.to_client(ops.Status("info", f"ok: {op.OP} {op.action}", id=op.id))

    def _unadvertise(self, op: ops.UnadvertiseAction) -> None:
        name = _name(op.action)
        if self.served.pop(name, None) is None:
            self.bridge.send_error(f"unadvertise_action: {name} is not served by this client",
                                   op.id)
            return
        for gid, goal in list(self.goals.items()):
            if goal.served == name:
                self._end(gid, _ABORTED, None)

    def _find(self, op: ops.ActionFeedback | ops.ActionResultOp) -> _Goal | None:
        goal = self.goals.get(str(op.id))
        if goal is None:
            self.bridge.send_error(f"{op.OP}: no goal {op.id!r} of {_name(op.action)} is waiting "
                               "on this client", op.id)
        return goal

    def _feedback(self, op: ops.ActionFeedback) -> None:
        goal = self._find(op)
        if goal is None:
            return
        problem = self.bridge.check(op.values, f"{goal.type_name}_Feedback", "values")
        if problem is not None:
            self.bridge.send_error(f"action_feedback for {goal.served}: {problem}", op.id)
            return
        if goal.feedback:
            self.bridge.to_client(ops.ActionFeedback(id=goal.caller_id,
                                                     action=goal.caller_action,
                                                     values=dict(op.values)))

    def _result(self, op: ops.ActionResultOp) -> None:
        goal = self._find(op)
        if goal is None:
            return
        status = op.status
        if status is None:
            status = _SUCCEEDED if op.result else _ABORTED
        elif status not in (_SUCCEEDED, _CANCELED, _ABORTED):
            self.bridge.send_error(
                f"action_result for {goal.served}: status {status} is not a final status "
                "(4 succeeded, 5 canceled, 6 aborted); the goal was aborted", op.id)
            status = _ABORTED
        elif not op.result and status == _SUCCEEDED:
            status = _ABORTED
        values = op.values if isinstance(op.values, Mapping) else None
        if values is not None:
            problem = self.bridge.check(values, f"{goal.type_name}_Result", "values")
            if problem is not None:
                self.bridge.send_error(
                    f"action_result for {goal.served}: {problem}; the goal was aborted", op.id)
                status, values = _ABORTED, None
        self._end(str(op.id), status, values)

    def _end(self, gid: str, status: int, values: Mapping[str, Any] | None) -> None:
        goal = self.goals.pop(gid)
        self._by_caller.pop(str(goal.caller_id), None)
        if values is None:  # what a ROS action client gets: the default result
            cls = self._cls(goal.type_name)
            values = cls.Result().to_json() if cls is not None else {}
        self._to_caller(goal.caller_id, goal.caller_action, dict(values), status)
