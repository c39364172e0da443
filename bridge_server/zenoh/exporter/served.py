"""Services and actions relays' clients serve: a service a relay's client serves is served
in ROS by the Graph's ``serve`` while its ``@serve`` token lives; each ROS call is a query
to the relay, the reply answers it. The first relay's token keeps a name, and a later one
(another relay's client) is refused with a put under ``@refused`` that its relay passes to
the client (put again while the token lives: a put can reach a relay before the network
routes it there). So is an action a relay's client serves (``serve_action``): each ROS goal
is a query to the relay whose replies stream the goal's feedback and its end; a ROS cancel
is a query."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
from typing import Any

import zenoh

from bridge_server.zenoh import keys
from bridge_server.zenoh.exporter.base import Served, json_bytes, log
from bridge_server.zenoh.exporter.graph import GraphOffer
from bridge_server.zenoh.exporter.policy import RelayPolicy
from bridge_server.zenoh.keys import GOAL_WAIT, Execute, GoalEvent
from bridge_server.zenoh.link import ignore_replies
from rosbridge_core.graph import RosCall, ServedAction, ServedGoal, ServedService
from rosbridge_core.interfaces import BridgeError, ConversionError, Kind
from rosbridge_core.protocol.goal_status import GoalStatus
from rosbridge_core.session.actions import ACTION_LINGER

__all__ = ["REFUSAL_REPEAT", "SERVED_CALL_WAIT", "ServedNames"]

SERVED_CALL_WAIT = 60.0
"""Seconds a ROS call of a relay-served service waits for the relay's reply (the relay's
session gives up sooner, after its ``served_call_timeout``; then the caller is not answered,
as on the bridge)."""

REFUSAL_REPEAT = (0.25, 4.0)
"""Seconds before a refusal under ``@refused`` is put again while the refused token lives,
first and at most (doubling): a put that came before the network routed it to the relay's
subscriber reached nobody, and the relay would believe its client serves the name."""

_GOAL_SERVICE = "/_action/send_goal"


class ServedNames(RelayPolicy, GraphOffer):
    """The exporter's part that serves in ROS what relays' clients serve."""

    _served_goals: dict[int, str]  # id(ServedGoal) -> its id in its query
    refusing: dict[str, asyncio.TimerHandle]
    """The next put of each refusal whose token lives, by the refusal's key."""
    _lingering: dict[str, ServedAction]
    _served_goal_ids: itertools.count[int]

    def _on_serve(self, sample: zenoh.Sample) -> None:
        try:
            relay, name, type_name = keys.parse_serve(str(sample.key_expr))
        except IndexError:
            return
        action = "/action/" in type_name
        key = name + _GOAL_SERVICE if action else name
        served = self.served.get(key)
        what = "action" if action else "service"
        kind: Kind = "action" if action else "srv"
        repeat = self.refusing.pop(keys.refused_key(self.robot, relay, name, kind), None)
        if repeat is not None:  # the refused token went, or comes again to be decided anew
            repeat.cancel()
        if sample.kind != zenoh.SampleKind.PUT:
            if served is not None and served.relay == relay:
                del self.served[key]
                self._unserve(key, served)
                self._refresh_snapshot()
                log.info("%s %s is no longer served through relay %s", what, name, relay)
            return
        if served is not None:
            if served.relay != relay:  # the first keeps it: the second relay's client is told
                self._refuse(relay, name, kind, f"{name} is already served by a client of "
                             f"relay {served.relay}; robot {self.robot} keeps the first")
            return
        refused = self.refusal("serve_action" if action else "serve_service", name, relay)
        if refused is None and self._served_in_ros(key) \
                and self.refusal("take_over", name, relay) is not None:
            role = self.policy()
            refused = (f"{what} {name} is served by a ROS node of robot {self.robot}, and its "
                       f"relay policy (role {role.name if role else 'gone'}) lets no relay take "
                       "it over (take_over)")
        if refused is not None:
            self._refuse(relay, name, kind, refused)
            return
        old = self._lingering.pop(key, None)
        if old is not None:  # two servers of one name would both answer each goal
            old.destroy()
        try:
            ros: ServedService | ServedAction
            if action:
                ros = self.graph.serve_action(
                    name, self.graph.resolve_action(type_name),
                    lambda goal: self._execute(name, relay, goal),
                    lambda goal: self._cancel_served(name, relay, goal))
            else:
                ros = self.graph.serve(name, self.graph.resolve_service(type_name),
                                       lambda call: self._forward(name, relay, call))
        except (BridgeError, ValueError) as exc:
            self._refuse(relay, name, kind, f"robot {self.robot} cannot serve {what} {name} "
                         f"({type_name}): {exc}")
            return
        self.served[key] = Served(relay, type_name, ros)
        self._refresh_snapshot()
        log.info("%s %s is served through relay %s", what, name, relay)

    def _refuse(self, relay: str, name: str, kind: Kind, why: str) -> None:
        """Tell ``relay`` that its client's ``@serve`` token of ``name`` is not taken
        (``why``): its session stops serving the name and tells the client, who would
        otherwise believe it serves and get no calls."""
        log.warning("relay %s's client serves %s, refused: %s", relay, name, why)
        self._put_refusal(keys.refused_key(self.robot, relay, name, kind), why.encode(),
                          REFUSAL_REPEAT[0])

    def _put_refusal(self, key: str, why: bytes, wait: float) -> None:
        """Put a refusal, and again after ``wait`` s (doubling) until its token goes."""
        if self.session is None:
            return
        with contextlib.suppress(zenoh.ZError):
            self.session.put(key, why)
        self.refusing[key] = self._loop.call_later(
            wait, self._put_refusal, key, why, min(2 * wait, REFUSAL_REPEAT[1]))

    def _unserve(self, key: str, served: Served) -> None:
        """A relay's client stopped serving: a service leaves ROS at once; an action's goals
        are aborted and its server lingers a moment, so ROS callers fetch those results (as
        on the bridge)."""
        ros = served.ros
        if not key.endswith(_GOAL_SERVICE):
            ros.destroy()
            return
        for goal in list(served.goals.values()):
            goal.finish(GoalStatus.ABORTED)
        served.goals.clear()
        action: ServedAction = ros  # type: ignore[assignment]
        action.alive = False
        self._lingering[key] = action
        self._loop.call_later(ACTION_LINGER, self._end_linger, key, action)

    def _end_linger(self, key: str, action: ServedAction) -> None:
        if self._lingering.get(key) is action:
            del self._lingering[key]
            action.destroy()

    def _forward(self, service: str, relay: str, call: RosCall) -> None:
        """A ROS call of a relay-served service: one query to the relay; its reply answers
        the caller, an error or no reply leaves it unanswered (as the bridge does)."""
        served = self.served.get(service)
        if served is None or served.relay != relay or self.session is None:
            log.warning("a ROS call to %s arrived after it went: not answered", service)
            return
        try:
            payload = json_bytes(call.served.request_conv.to_obj(call.request))
        except Exception:
            log.exception("cannot convert a request to %s", service)
            return

        def answer(reply: zenoh.Reply) -> None:
            if reply.ok is None:
                text = reply.err.payload.to_string() if reply.err is not None else "?"
                log.warning("relay %s failed a call of %s (%.200s): the ROS caller is not "
                            "answered", relay, service, text)
                return
            try:
                obj = json.loads(reply.ok.payload.to_bytes())
                call.complete(call.served.response_conv.from_obj(obj, "response"))
            except (ValueError, ConversionError) as exc:
                log.warning("relay %s answered %s with a bad response (%s): the ROS caller "
                            "is not answered", relay, service, exc)

        self.session.get(keys.key_of(self.robot, service, f"{keys.SERVING}/{relay}"),
                         self._on_loop(answer), payload=payload,
                         timeout=SERVED_CALL_WAIT)

    def _execute(self, action: str, relay: str, goal: ServedGoal) -> None:
        """A ROS goal of a relay-served action: one query to the relay, its replies the
        goal's feedback and end; a query that ends without a result aborts the goal."""
        if self.session is None:
            goal.finish(GoalStatus.ABORTED)
            return
        gid = f"{self.epoch}{next(self._served_goal_ids)}"
        self._served_goals[id(goal)] = gid
        served = self.served.get(action + _GOAL_SERVICE)
        if served is not None:
            served.goals[id(goal)] = goal
        conv = goal.served

        def answer(reply: zenoh.Reply) -> None:
            try:
                if reply.ok is None:
                    raise BridgeError(reply.err.payload.to_string() if reply.err else "?")
                event = GoalEvent.decode(reply.ok.payload.to_bytes())
                if event.event == "feedback":
                    goal.feedback(conv.feedback_conv.from_obj(event.values, "feedback"))
                elif event.event == "result":
                    result = None
                    if event.values is not None:
                        result = conv.result_conv.from_obj(event.values, "result")
                    goal.finish(event.status, result)
            except BridgeError as exc:  # ConversionError too
                log.warning("relay %s's goal %s of %s: %s; the goal is aborted", relay, gid,
                            action, exc)
                goal.finish(GoalStatus.ABORTED)

        def ended(_: Any = None) -> None:
            self._served_goals.pop(id(goal), None)
            if served is not None:
                served.goals.pop(id(goal), None)
            if goal.finish(GoalStatus.ABORTED):
                log.warning("relay %s ended goal %s of %s without a result: aborted", relay,
                            gid, action)

        self.session.get(keys.key_of(self.robot, action, f"{keys.EXECUTING}/{relay}"),
                         zenoh.handlers.Callback(self._cross(answer),
                                                 lambda: self._cross(ended)(None),
                                                 indirect=False),
                         payload=Execute(gid, goal=conv.goal_conv.to_obj(goal.request)).encode(),
                         timeout=GOAL_WAIT, consolidation=zenoh.ConsolidationMode.NONE)

    def _cancel_served(self, action: str, relay: str, goal: ServedGoal) -> None:
        """A ROS caller cancels a goal of a relay-served action: the relay's client hears it
        (and decides how the goal ends)."""
        gid = self._served_goals.get(id(goal))
        if gid is not None and self.session is not None:
            self.session.get(keys.key_of(self.robot, action, f"{keys.EXECUTING}/{relay}"),
                             ignore_replies, payload=Execute(gid, cancel=True).encode(),
                             timeout=SERVED_CALL_WAIT)
