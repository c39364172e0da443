"""The ROS side of actions: rclpy action clients and servers, driven from the asyncio loop.

rclpy's action classes are not thread safe, so every call into them runs on
the executor thread (:meth:`RosNode.in_executor`); everything they report
crosses back to the loop with :meth:`RosNode.post`. The loop never waits on
the executor.

* :class:`SharedActionClient`: one rclpy ``ActionClient`` per (action, type)
  for every session. :meth:`SharedActionClient.send` returns a
  :class:`SentGoal`; its :class:`GoalListener` hears, on the loop, whether the
  goal was accepted, each feedback, the cancel answer and the final
  (status, result).
* :class:`ServedAction`: an rclpy ``ActionServer`` whose goals are carried
  out by a websocket client. rclpy would run an execute callback as an
  executor task, and a pending coroutine task makes rclpy's executor spin
  without waiting; so goals are never "executed" in rclpy's sense: the goal
  is moved to EXECUTING when accepted, and its terminal state and result are
  set when the client answers (:meth:`ServedGoal.finish`).
"""

from __future__ import annotations

import contextlib
import importlib
import logging
import secrets
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from unique_identifier_msgs.msg import UUID

from bridge_server.rclpy_graph import convert
from bridge_server.rclpy_graph.qos import SERVICE_DEPTH, qos_profile
from rosbridge_core.graph import ACTIVE, GoalListener
from rosbridge_core.interfaces import BridgeError
from rosbridge_core.protocol.goal_status import GoalStatus

if TYPE_CHECKING:
    from bridge_server.rclpy_graph.node import RosNode

__all__ = [
    "ACTIVE",
    "GoalListener",
    "GoalStatus",
    "SentGoal",
    "ServedAction",
    "ServedGoal",
    "SharedActionClient",
]

log = logging.getLogger("bridge_server.rclpy_graph.actions")

_action: Any = importlib.import_module("rclpy.action")  # untyped API, used as Any

FEEDBACK_DEPTH = 1000
"""History depth of the bridge's feedback publishers and subscriptions (bursts of feedback)."""

RESULT_TIMEOUT = 60
"""Seconds a finished served goal's result stays available to ROS callers."""

PROBE_INTERVAL = 0.2
"""Seconds between probes of a new server's reply path (:meth:`SharedActionClient.ready`)."""

PROBE_GIVE_UP = 3.0
"""Seconds after which a server that never answers the probe is trusted anyway."""

FEEDBACK_GRACE = 0.005
"""Seconds a goal's feedback is still heard after its result (only goals that asked for
feedback wait this long for their result)."""


def check_rclpy_internals() -> None:
    """Fail at start-up, clearly, if rclpy's private action internals used here differ
    (``_feedback_callbacks``, ``_client_handle``, ``_result_futures``, ``_update_state``,
    ``_get_result_async`` and ``GoalEvent``: tested with the rclpy the ``bridge`` extra pins).
    Raises :class:`BridgeError`.
    """
    import inspect
    from importlib.metadata import PackageNotFoundError, version

    missing = [n for n in ("EXECUTE", "CANCEL_GOAL") if not hasattr(_rclpy.GoalEvent, n)]
    if not callable(getattr(_action.server.ServerGoalHandle, "_update_state", None)):
        missing.append("ServerGoalHandle._update_state")
    if not callable(getattr(_action.ActionClient, "_get_result_async", None)):
        missing.append("ActionClient._get_result_async")
    for cls, attrs in ((_action.ActionClient, ("_feedback_callbacks", "_client_handle")),
                       (_action.ActionServer, ("_result_futures",))):
        try:
            source = inspect.getsource(cls.__init__)
        except (OSError, TypeError):
            source = ""
        missing += [f"{cls.__name__}.{a}" for a in attrs if f"self.{a}" not in source]
    if missing:
        try:
            installed = version("ros-rclpy")
        except PackageNotFoundError:
            installed = "(not from PyPI)"
        raise BridgeError(
            f"rclpy {installed} lacks what the bridge's actions build on "
            f"({', '.join(missing)}); install the rclpy of the 'bridge' extra (pyproject.toml)"
        )




def _action_qos() -> dict[str, Any]:
    services = qos_profile(True, False, SERVICE_DEPTH)
    return {
        "goal_service_qos_profile": services,
        "result_service_qos_profile": services,
        "cancel_service_qos_profile": services,
    }


class SentGoal:
    """A goal the bridge sent to a ROS action server; ``cancel()`` may come at any time."""

    def __init__(self, shared: SharedActionClient, goal: Any, listener: GoalListener,
                 feedback: bool) -> None:
        self.shared = shared
        self.goal = goal
        self.listener = listener
        self.feedback = feedback
        self.handle: Any = None  # the rclpy ClientGoalHandle, once accepted (executor thread)
        self.callback: Callable[[Any], None] | None = None  # feedback, if asked for
        self.cancel_wanted = False
        self.finished = False

    def cancel(self) -> None:
        """Ask the action server to cancel the goal (before or after it was accepted)."""
        self.shared.ros.in_executor(self.shared._cancel, self)


class _ActionEnd:
    """What both ends of an action know: its name, class and converters (built once)."""

    def __init__(self, ros: RosNode, name: str, action_cls: type[Any]) -> None:
        self.ros = ros
        self.name = name
        self.action_cls = action_cls
        self.goal_conv = convert.converter_for(action_cls.Goal)
        self.feedback_conv = convert.converter_for(action_cls.Feedback)
        self.result_conv = convert.converter_for(action_cls.Result)


class SharedActionClient(_ActionEnd):
    """The bridge's rclpy action client for one action name and type."""

    def __init__(self, ros: RosNode, name: str, action_cls: type[Any]) -> None:
        super().__init__(ros, name, action_cls)
        self.client: Any = None
        self.confirmed = False  # a server answered the probe (loop thread)
        self._probe_first = 0.0  # loop times of the first and the latest probe
        self._probe_last = 0.0
        self._probes: list[Any] = []  # probe futures not answered yet (executor thread)
        # Made on the executor thread, like every later use: rclpy's ActionClient joins
        # the executor's wait set unsafely when made from another thread (ros2/rclpy#1589).
        # Goals sent before it exists queue behind this hand-off.
        ros.in_executor(self._create)

    def _create(self) -> None:
        self.client = _ActionClient(
            self.ros.node, self.action_cls, self.name,
            feedback_sub_qos_profile=qos_profile(True, False, FEEDBACK_DEPTH), **_action_qos(),
            callback_group=_own_group(),
        )

    def matched(self) -> bool:
        """Whether DDS has matched an action server to this client (loop thread)."""
        try:
            return bool(self.client.server_is_ready())
        except Exception:
            return False

    def ready(self) -> bool:
        """Whether an action server is matched and its answers reach us (loop thread).

        DDS can match our requests to a new server before that server has matched
        our reply readers; a goal sent in that window is accepted but its answer is
        lost. So a newly matched server is first asked, every ``PROBE_INTERVAL`` s
        until it answers, for the result of a goal that does not exist (harmless,
        answered at once with STATUS_UNKNOWN). The result service's reply reader is
        announced after the goal service's, so its answer shows the goal path
        works too. A server that never answers is trusted after ``PROBE_GIVE_UP`` s.
        """
        if not self.matched():
            self.confirmed = False  # a server that comes (back) is probed again
            self._probe_first = 0.0
            return False
        if self.confirmed:
            return True
        now = self.ros.loop.time()
        if not self._probe_first:
            self._probe_first = now
        elif now - self._probe_first >= PROBE_GIVE_UP:
            log.debug("the action server of %s did not answer a probe; trusting it", self.name)
            self._confirm()
            return True
        if now - self._probe_last >= PROBE_INTERVAL:
            self._probe_last = now
            self.ros.in_executor(self._probe)
        return False

    def _confirm(self) -> None:
        """On the loop: the reply path works; forget the probes still waiting."""
        if not self.confirmed:
            self.confirmed = True
            self.ros.in_executor(self._forget_probes)

    def send(self, goal: Any, listener: GoalListener, feedback: bool) -> SentGoal:
        """Send ``goal`` (an instance of the action's ``Goal``) now; ``listener`` hears the rest."""
        sent = SentGoal(self, goal, listener, feedback)
        self.ros.in_executor(self._send, sent)
        return sent

    # -- executor thread ---------------------------------------------------------------------

    def _send(self, sent: SentGoal) -> None:
        post = self.ros.post
        if sent.cancel_wanted:  # canceled before it left the bridge
            sent.finished = True
            post(sent.listener.on_result, GoalStatus.CANCELED, None)
            return
        listener = sent.listener
        callback: Callable[[Any], None] | None = None
        if sent.feedback:

            def callback(msg: Any) -> None:
                post(listener.on_feedback, msg.feedback)

        sent.callback = callback
        try:
            future = self.client.send_goal_async(sent.goal, feedback_callback=callback)
        except Exception as exc:
            log.warning("sending a goal to %s failed: %s", self.name, exc)
            sent.finished = True
            post(listener.on_result, GoalStatus.ABORTED, None)
            return
        self._inline(future)
        future.add_done_callback(lambda f: self._answered(sent, f))

    def _answered(self, sent: SentGoal, future: Any) -> None:
        post = self.ros.post
        handle = None if future.exception() is not None else future.result()
        if handle is None or not handle.accepted:
            sent.finished = True
            post(sent.listener.on_rejected)
            return
        sent.handle = handle
        post(sent.listener.on_accepted)
        result_future = handle.get_result_async()
        self._inline(result_future)
        result_future.add_done_callback(lambda f: self._result(sent, f))
        if sent.cancel_wanted:
            self._cancel(sent)

    def _result(self, sent: SentGoal, future: Any) -> None:
        sent.finished = True
        if future.exception() is not None:
            self.ros.post(sent.listener.on_result, GoalStatus.ABORTED, None)
            return
        response = future.result()
        if sent.callback is not None:
            # rclpy forgot the goal's feedback callback with the result, but feedback it
            # took in this same round is delivered after this; keep hearing it.
            self.client._feedback_callbacks[bytes(sent.handle.goal_id.uuid)] = sent.callback
        self.ros.in_executor(self._report, sent, int(response.status), response.result)

    def _report(self, sent: SentGoal, status: int, result: Any) -> None:
        """Next executor round: deliver waiting feedback, then the result."""
        self._drain_feedback()
        if sent.callback is None:
            self.ros.post(sent.listener.on_result, status, result)
            return
        # Feedback still in transit (a topic, while the result is a service reply) is
        # heard a moment longer.
        self.ros.post(self._after_grace, sent, bytes(sent.handle.goal_id.uuid), status, result)

    def _after_grace(self, sent: SentGoal, uuid: bytes, status: int, result: Any) -> None:
        """On the loop: report the result once late feedback had ``FEEDBACK_GRACE`` s."""

        def report() -> None:
            self.ros.in_executor(self.client._feedback_callbacks.pop, uuid, None)
            sent.listener.on_result(status, result)

        self.ros.loop.call_later(FEEDBACK_GRACE, report)

    def _probe(self) -> None:
        handle = _action.client.ClientGoalHandle(
            self.client, UUID(uuid=list(secrets.token_bytes(16))),
            self.action_cls.Impl.SendGoalService.Response(),
        )
        try:
            future = self.client._get_result_async(handle)
        except Exception as exc:
            log.debug("probing the action server of %s failed: %s", self.name, exc)
            return
        self._inline(future)
        self._probes.append(future)
        future.add_done_callback(lambda _f: self.ros.post(self._confirm))

    def _forget_probes(self) -> None:
        for future in self._probes:
            if not future.done():
                with contextlib.suppress(Exception):
                    self.client._remove_pending_result_request(future)
        self._probes.clear()

    def _inline(self, future: Any) -> None:
        """Run ``future``'s done callbacks right where rclpy completes it (executor thread).

        rclpy would schedule each as an executor task: one more wait-set round each,
        per goal answer, result and cancel answer. (:class:`_ActionClient` lets rclpy's
        own clean-up callback find the future gone.)
        """
        with contextlib.suppress(ValueError):
            self.client.remove_future(future)

    def _drain_feedback(self) -> None:
        """Deliver feedback that is already waiting, so it goes out before the result.

        Feedback (a topic) and the result (a service response) travel apart; rclpy takes
        one feedback per executor round, so a burst would otherwise follow the result.
        """
        client = self.client
        feedback_cls = self.action_cls.Impl.FeedbackMessage
        with contextlib.suppress(Exception):
            for _ in range(FEEDBACK_DEPTH):
                msg = client._client_handle.take_feedback(feedback_cls)
                if msg is None:
                    break
                callback = client._feedback_callbacks.get(bytes(msg.goal_id.uuid))
                if callback is not None:
                    callback(msg)

    def _cancel(self, sent: SentGoal) -> None:
        sent.cancel_wanted = True
        if sent.handle is None or sent.finished:
            return  # sent on acceptance (or moot)
        try:
            future = sent.handle.cancel_goal_async()
        except Exception as exc:
            log.debug("cancel request for a goal of %s failed: %s", self.name, exc)
            return

        self._inline(future)

        def answered(f: Any) -> None:
            if f.exception() is None and f.result() is not None:
                self.ros.post(sent.listener.on_cancel_answer, int(f.result().return_code))

        future.add_done_callback(answered)

    def destroy(self) -> None:
        """Remove the rclpy action client (executor thread)."""
        self.ros.in_executor(self._destroy)

    def _destroy(self) -> None:
        with contextlib.suppress(Exception):
            self.client.destroy()


class ServedGoal:
    """A ROS caller's goal to an action a websocket client serves."""

    def __init__(self, served: ServedAction, handle: Any) -> None:
        self.served = served
        self.handle = handle
        self.request = handle.request
        self.done = False

    def feedback(self, msg: Any) -> None:
        """Publish one feedback message (an instance of the action's ``Feedback``).

        Published from the calling thread: a publish is thread safe in rcl, and a hop
        through the executor per message would hold feedback back under load.
        """
        if self.done:
            return
        with contextlib.suppress(Exception):  # the goal may have finished meanwhile
            self.handle.publish_feedback(msg)

    def finish(self, status: int, result: Any | None = None) -> bool:
        """End the goal with a terminal ``status`` and ``result`` (``None``: default values).

        False if it had already finished.
        """
        if self.done:
            return False
        self.done = True
        self.served.ros.in_executor(self.served._finish, self, status, result)
        return True


class ServedAction(_ActionEnd):
    """An rclpy action server whose goals a websocket client carries out.

    ``on_goal`` and ``on_cancel`` are called on the loop with the
    :class:`ServedGoal`. Every goal is accepted while the action is served,
    every cancel request is accepted (the client decides how the goal ends).
    """

    def __init__(
        self,
        ros: RosNode,
        name: str,
        action_cls: type[Any],
        on_goal: Callable[[ServedGoal], None],
        on_cancel: Callable[[ServedGoal], None],
    ) -> None:
        super().__init__(ros, name, action_cls)
        self.on_goal = on_goal
        self.on_cancel = on_cancel
        self.alive = True
        self._goals: dict[bytes, ServedGoal] = {}
        self.server: Any = None
        # Made on the executor thread (see SharedActionClient); goals can only arrive after.
        # Two hand-offs, as destroying takes two (:meth:`_destroy`): a server re-advertised
        # under the name of one just unadvertised comes after the old one is gone, so ROS
        # callers never meet two servers answering one goal.
        ros.in_executor(ros.in_executor, self._create)

    def _create(self) -> None:
        self.server = _action.ActionServer(
            self.ros.node, self.action_cls, self.name, _never_executed,
            callback_group=_own_group(),
            goal_callback=self._goal_callback,
            handle_accepted_callback=self._accepted,
            cancel_callback=self._cancel_callback,
            feedback_pub_qos_profile=qos_profile(True, False, FEEDBACK_DEPTH),
            result_timeout=RESULT_TIMEOUT,
            **_action_qos(),
        )

    # -- executor thread ---------------------------------------------------------------------

    def _goal_callback(self, _goal: Any) -> Any:
        return _action.GoalResponse.ACCEPT if self.alive else _action.GoalResponse.REJECT

    def _accepted(self, handle: Any) -> None:
        goal = ServedGoal(self, handle)
        self._goals[bytes(handle.goal_id.uuid)] = goal
        if not handle.is_cancel_requested:
            handle._update_state(_rclpy.GoalEvent.EXECUTE)
        if not self.alive:
            goal.done = True
            self._finish(goal, GoalStatus.ABORTED, None)
            return
        self.ros.post(self.on_goal, goal)

    def _cancel_callback(self, handle: Any) -> Any:
        goal = self._goals.get(bytes(handle.goal_id.uuid))
        if goal is not None and not goal.done:
            self.ros.post(self.on_cancel, goal)
        return _action.CancelResponse.ACCEPT

    def _finish(self, goal: ServedGoal, status: int, result: Any | None) -> None:
        handle = goal.handle
        self._goals.pop(bytes(handle.goal_id.uuid), None)
        if not handle.is_active:
            return
        try:
            if status == GoalStatus.SUCCEEDED:
                handle.succeed()
            elif status == GoalStatus.CANCELED:
                if not handle.is_cancel_requested:
                    handle._update_state(_rclpy.GoalEvent.CANCEL_GOAL)
                handle.canceled()
            else:
                handle.abort()
        except Exception as exc:  # an invalid transition: end it as aborted
            log.debug("goal of %s: %s; aborting it", self.name, exc)
            with contextlib.suppress(Exception):
                handle.abort()
        response = self.action_cls.Impl.GetResultService.Response()
        response.status = handle.status
        response.result = result if result is not None else self.action_cls.Result()
        future = self.server._result_futures.get(bytes(handle.goal_id.uuid))
        if future is not None and not future.done():
            future.set_result(response)

    # -- loop thread -------------------------------------------------------------------------

    def destroy(self) -> None:
        """Remove the rclpy action server (goals still open are aborted first)."""
        self.alive = False
        self.ros.in_executor(self._destroy)

    def _destroy(self) -> None:
        for goal in list(self._goals.values()):
            goal.done = True
            self._finish(goal, GoalStatus.ABORTED, None)
        # The result responses just scheduled go out first (executor tasks run before
        # the next hand-off), then the server goes.
        self.ros.in_executor(self._destroy_server)

    def _destroy_server(self) -> None:
        with contextlib.suppress(Exception):
            self.server.destroy()


def _remove_future_if_present(self: Any, future: Any) -> None:
    with contextlib.suppress(ValueError):
        self._futures.remove(future)


_ActionClient: Any = type("_ActionClient", (_action.ActionClient,), {
    "__doc__": """rclpy's ``ActionClient``; its ``remove_future`` accepts a future already gone.

    :meth:`SharedActionClient._inline` takes each request's future out of the client's
    futures; rclpy's own done callback removes it again, and the ``ValueError`` that
    raises there skipped the rest of rclpy's clean-up, keeping every goal's sequence
    number entry for ever (and warning once per goal).
    """,
    "remove_future": _remove_future_if_present,
})


def _own_group() -> Any:
    """A callback group for one action end.

    rclpy leaves a callback group busy for ever when taking from an action end
    fails; with a group of its own, such a failure stalls that action only, never
    the node's default group that every topic and service of the bridge is in.
    """
    group: Any = importlib.import_module("rclpy.callback_groups").MutuallyExclusiveCallbackGroup()
    return group


def _never_executed(_handle: Any) -> Any:  # pragma: no cover - goals are finished directly
    raise RuntimeError("served goals are not executed by rclpy")
