"""Actions of the in-memory graph: :class:`MemoryActionClient` and the goals it sends
(:class:`MemorySentGoal`), :class:`MemoryServedAction` (an action a session serves) and its goals
(:class:`MemoryServedGoal`), with feedback, cancel (also through
``<action>/_action/cancel_goal``, by action_msgs' policy), results and ``GoalStatus``."""

from __future__ import annotations

import asyncio
import secrets
import time
from collections.abc import Callable, Mapping
from typing import Any, Protocol

from msgs.runtime import Action
from rosbridge_core.graph import ACTIVE, GoalListener, ServedGoal
from rosbridge_core.interfaces import ServiceCallError
from rosbridge_core.memory.services import ServiceServer, ServingNode
from rosbridge_core.protocol.goal_status import GoalStatus

__all__ = ["MemoryActionClient", "MemorySentGoal", "MemoryServedAction", "MemoryServedGoal"]

_ACTION_SERVICES = {"send_goal": "_SendGoal", "cancel_goal": None, "get_result": "_GetResult"}
_CANCEL_TYPE = "action_msgs/srv/CancelGoal"


class _ActionRegistry(Protocol):
    """What an action needs of the whole graph (:class:`~.graph.MemoryRos`)."""

    @property
    def actions(self) -> Mapping[str, list[MemoryServedAction]]: ...

    def remove_action(self, action: MemoryServedAction) -> None: ...


class _ActionNode(ServingNode, Protocol):
    """What an action client or server needs of its node (:class:`~.graph.MemoryGraph`)."""

    @property
    def ros(self) -> _ActionRegistry: ...

    def resolve_service(self, name: str) -> Any: ...


class _Handle:
    """A goal's id as the sessions read it (``handle.goal_id.uuid``)."""

    def __init__(self, uuid: bytes) -> None:
        self.goal_id = self
        self.uuid = uuid


class MemorySentGoal:
    """A goal sent through a :class:`MemoryActionClient`."""

    def __init__(self, shared: MemoryActionClient, listener: GoalListener,
                 feedback: bool) -> None:
        self.shared = shared
        self.listener = listener
        self.feedback = feedback
        self.handle: _Handle | None = None
        self.served: MemoryServedGoal | None = None
        self.cancel_wanted = False

    def cancel(self) -> None:
        """Ask the server to cancel the goal (before or after it was accepted)."""
        self.cancel_wanted = True
        served = self.served
        if served is not None and served.status in ACTIVE:
            self.listener.on_cancel_answer(served.served.cancel(served))


class MemoryActionClient:
    """A client of one action (of one type) in the graph."""

    def __init__(self, graph: _ActionNode, name: str, action_cls: type[Action]) -> None:
        self.graph = graph
        self.name = name
        self.action_cls = action_cls
        self.feedback_conv = graph.converter(action_cls.Feedback)
        self.result_conv = graph.converter(action_cls.Result)

    def _server(self) -> MemoryServedAction | None:
        return next((a for a in self.graph.ros.actions.get(self.name, [])
                     if a.action_cls is self.action_cls and a.alive), None)

    def matched(self) -> bool:
        """Whether a server of the action and its type is in the graph."""
        return self._server() is not None

    def ready(self) -> bool:
        """As :meth:`matched`: a goal sent now reaches it."""
        return self.matched()

    def send(self, goal: Any, listener: GoalListener, feedback: bool) -> MemorySentGoal:
        """Send ``goal``; it is accepted (or fails: no server) on the loop's next turn."""
        sent = MemorySentGoal(self, listener, feedback)
        self.graph.loop.call_soon(self._deliver, sent, goal)
        return sent

    def _deliver(self, sent: MemorySentGoal, goal: Any) -> None:
        server = self._server()
        if server is None:
            sent.listener.on_failed(f"action {self.name} has no action server in the graph")
            return
        server.take(goal, sent)

    def destroy(self) -> None:
        """Nothing to remove: each goal holds its own way back."""


class MemoryServedGoal:
    """A goal of an action a session serves."""

    def __init__(self, served: MemoryServedAction, request: Any, uuid: bytes,
                 sent: MemorySentGoal | None) -> None:
        self.served = served
        self.request = request
        self.uuid = uuid
        self.sent = sent
        self.stamp_ns = time.time_ns()
        self.status = GoalStatus.EXECUTING
        self.result: asyncio.Future[tuple[int, Any]] = served.graph.loop.create_future()

    def feedback(self, msg: Any) -> None:
        """One feedback message to the goal's client (if it asked for feedback)."""
        sent = self.sent
        if self.status in ACTIVE and sent is not None and sent.feedback:
            sent.listener.on_feedback(msg)

    def finish(self, status: int, result: Any | None = None) -> bool:
        """End the goal with ``status`` (``None`` result: default values); False if it had
        ended."""
        if self.status not in ACTIVE:
            return False
        self.status = GoalStatus(status)
        result = result if result is not None else self.served.action_cls.Result()
        self.served.goals.pop(self.uuid, None)
        self.result.set_result((int(status), result))
        if self.sent is not None:
            self.sent.listener.on_result(int(status), result)
        return True


class MemoryServedAction:
    """An action of the graph whose goals and cancel requests go to the callbacks; every
    goal is accepted while it is served, every cancel request too."""

    def __init__(self, graph: _ActionNode, name: str, action_cls: type[Action],
                 on_goal: Callable[[ServedGoal], None],
                 on_cancel: Callable[[ServedGoal], None]) -> None:
        self.graph = graph
        self.name = name
        self.action_cls = action_cls
        self.goal_conv = graph.converter(action_cls.Goal)
        self.feedback_conv = graph.converter(action_cls.Feedback)
        self.result_conv = graph.converter(action_cls.Result)
        self.on_goal = on_goal
        self.on_cancel = on_cancel
        self.alive = True
        self.goals: dict[bytes, MemoryServedGoal] = {}
        base = f"{name}/_action/"
        self.servers = [
            ServiceServer(graph, base + "cancel_goal", _CANCEL_TYPE, self._cancel_service),
            *(ServiceServer(graph, base + part, action_cls._type + suffix, self._internal)
              for part, suffix in _ACTION_SERVICES.items() if suffix is not None),
        ]

    def take(self, goal: Any, sent: MemorySentGoal | None) -> MemoryServedGoal:
        """A goal accepted: handed to ``on_goal`` (a cancel asked before it came follows)."""
        uuid = secrets.token_bytes(16)
        served = self.goals[uuid] = MemoryServedGoal(self, goal, uuid, sent)
        if sent is not None:
            sent.served = served
            sent.handle = _Handle(uuid)
            sent.listener.on_accepted()
        self.on_goal(served)
        if sent is not None and sent.cancel_wanted:
            sent.cancel()
        return served

    def cancel(self, goal: MemoryServedGoal) -> int:
        """A cancel request for ``goal``: ``CancelGoal`` return code (0: canceling)."""
        if goal.status not in ACTIVE:
            return 3
        if goal.status != GoalStatus.CANCELING:
            goal.status = GoalStatus.CANCELING
            self.on_cancel(goal)
        return 0

    async def _cancel_service(self, request: Any) -> Any:
        """``<action>/_action/cancel_goal``: action_msgs' policy by goal id and stamp."""
        info = request.goal_info
        uuid = bytes(info.goal_id.uuid)
        stamp = info.stamp.sec * 1_000_000_000 + info.stamp.nanosec
        if any(uuid):
            picked = [g for g in [self.goals.get(uuid)] if g is not None]
            if not picked:
                return _cancel_response(self, 2, [])
        else:
            picked = [g for g in self.goals.values() if not stamp or g.stamp_ns <= stamp]
        canceling = [g for g in picked if self.cancel(g) == 0]
        for g in canceling:
            if g.sent is not None:
                g.sent.listener.on_cancel_answer(0)
        return _cancel_response(self, 0 if canceling or not any(uuid) else 3, canceling)

    async def _internal(self, request: Any) -> Any:
        raise ServiceCallError(f"{self.name}: the in-memory graph answers only cancel_goal of "
                               "an action's services as a service (send goals as goals)")

    def destroy(self) -> None:
        """Remove the action server; open goals are aborted."""
        self.alive = False
        for goal in list(self.goals.values()):
            goal.finish(GoalStatus.ABORTED)
        self.graph.ros.remove_action(self)


def _cancel_response(action: MemoryServedAction, code: int,
                     goals: list[MemoryServedGoal]) -> Any:
    cls = action.graph.resolve_service(_CANCEL_TYPE).Response
    return cls.from_json({"return_code": code, "goals_canceling": [
        {"goal_id": {"uuid": list(g.uuid)},
         "stamp": {"sec": g.stamp_ns // 1_000_000_000, "nanosec": g.stamp_ns % 1_000_000_000}}
        for g in goals]})

