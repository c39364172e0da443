"""Service calls: a relay's call is a query, answered by the Graph's own ``call_service``
(held to the robot's relay policy, and a relay cancels its own goals only)."""

from __future__ import annotations

from typing import Any

import zenoh

from bridge_server.zenoh import keys
from bridge_server.zenoh.exporter.actions import RobotGoal
from bridge_server.zenoh.exporter.base import json_bytes
from bridge_server.zenoh.exporter.policy import RelayPolicy
from bridge_server.zenoh.keys import CallRequest
from bridge_server.zenoh.link import answering
from rosbridge_core.interfaces import BridgeError

__all__ = ["ServiceCalls"]

_CANCEL_SERVICE = "/_action/cancel_goal"


class ServiceCalls(RelayPolicy):
    """The exporter's part that answers relays' service calls."""

    goals: dict[tuple[str, str], RobotGoal]
    """Relays' goals in flight (:class:`~.actions.RelayGoals`'): a call of an action's
    ``cancel_goal`` reaches only the calling relay's."""

    def _answer_call(self, query: zenoh.Query) -> None:
        self._spawn(self._call(query))

    async def _call(self, query: zenoh.Query) -> None:
        with answering(query):
            try:
                relay, service = keys.parse_scoped(str(query.key_expr))
                req = CallRequest.decode(query.payload.to_bytes() if query.payload else b"")
                refused = self.refusal("call_service", service, relay)
                if refused is not None:
                    raise BridgeError(refused)
                response = await self.graph.call_service(
                    service, req.type, req.args, req.timeout, req.discovery_wait,
                    check=lambda request: self._not_its_goal(relay, service, request))
            except Exception as exc:  # rclpy's own (a name it refuses) too: the relay's
                query.reply_err(str(exc).encode())  # caller gets the text, not silence
                return
            query.reply(query.key_expr, json_bytes(response))

    def _not_its_goal(self, relay: str, service: str, request: Any) -> str | None:
        """Why ``relay`` may not send ``request`` to ``service``: a call of an action's
        ``cancel_goal`` that reaches a goal another relay sent (a relay acts on its own goals
        only; a zero goal id or a stamp cancels every goal, theirs too). ``None``: it may
        (the robot's relay policy decides the rest)."""
        action = service.removesuffix(_CANCEL_SERVICE)
        theirs = [g for g in self.goals.values() if g.action == action and g.key[0] != relay]
        if action == service or not theirs:
            return None
        info = getattr(request, "goal_info", None)
        uuid = bytes(info.goal_id.uuid) if info is not None else b""
        if info is None or info.stamp.sec or info.stamp.nanosec or not any(uuid):
            owners = ", ".join(sorted({g.key[0] for g in theirs}))
            return (f"relay {relay} may not cancel every goal of {action}: a zero goal id or a "
                    f"stamp would cancel goals relay {owners} sent, and a relay acts on its own "
                    "goals only (give one goal's id and a zero stamp)")
        for goal in theirs:
            handle = goal.sent.handle if goal.sent is not None else None
            if handle is not None and bytes(handle.goal_id.uuid) == uuid:
                return (f"goal {uuid.hex()} of {action} was sent through relay {goal.key[0]}: "
                        f"relay {relay} may not cancel it (a relay acts on its own goals only)")
        return None
