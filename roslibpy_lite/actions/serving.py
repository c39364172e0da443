"""Serving an action (:class:`ActionServer`, made by ``ros.advertise_action``) and what its
handler gets with each goal (:class:`GoalContext`)."""

from __future__ import annotations

import asyncio
import concurrent.futures
import inspect
import logging
from collections.abc import Callable, Mapping
from typing import Any, Protocol, Self

from msgs.runtime import Action, Message
from rosbridge_core.protocol import ops
from rosbridge_core.protocol.goal_status import GoalStatus

from .._aio import is_async_callable, running_loop
from ..exceptions import RosLibError, UsageError
from ..handles.base import _BridgeHandle
from ..messages import check_dict, from_wire, to_wire
from .goals import GoalBackend, _action_class, _part

log = logging.getLogger("roslibpy_lite.client")

ACTION_HANDLER_THREADS = 32
"""Goals one action server runs at once with a plain (not ``async``) handler; more wait."""

ActionHandler = Callable[[Any, "GoalContext"], Any]
"""An action handler: ``fn(goal, ctx) -> result``, sync (run in a thread) or ``async``."""


# --- serving actions -------------------------------------------------------------------------

class ActionBackend(GoalBackend, Protocol):
    """What goals and served actions need from the capability that made them
    (:class:`~roslibpy_lite.capabilities.actions.Actions`)."""

    @property
    def validate(self) -> bool:
        """Whether dicts are checked against their type's ``msgs`` class."""
        ...

    def forget_action(self, server: ActionServer) -> None:
        """Forget a served action and tell the bridge."""
        ...

    def served_goal_done(self, ctx: GoalContext, op: ops.ActionResultOp | None) -> None:
        """A served goal's handler returned: send ``op`` (None: the goal was lost)."""
        ...


class GoalContext:
    """What an action handler gets next to the goal: feedback out, cancel requests in."""

    def __init__(self, server: ActionServer, id: str, loop: asyncio.AbstractEventLoop) -> None:
        self.server = server
        self.id = id
        """The bridge's id of this goal (opaque)."""
        self.action = server.action
        self.cancel_requested = False
        """True once a ROS caller asked to cancel (or the connection dropped)."""
        self._loop = loop
        self._cancel = asyncio.Event()
        self.lost = False

    def publish_feedback(self, feedback: Mapping[str, Any] | Message) -> None:
        """Send feedback to the caller (a dict or ``Feedback`` instance; any thread).

        Raises:
            InvalidMessageError / UsageError: feedback that does not fit the type.
        """
        server = self.server
        cls = _part(server.action_cls, "Feedback")
        what = f"feedback of {server.action}"
        wire = to_wire(feedback, f"{server.type_name}_Feedback", cls, what)
        if cls is None and server._backend.validate:
            check_dict(wire, _part(_action_class(server.type_name), "Feedback"), what)
        op = ops.ActionFeedback(id=self.id, action=server.action, values=wire)
        if running_loop() is self._loop:
            self._send(op)
        else:
            self._loop.call_soon_threadsafe(self._send, op)

    def _send(self, op: ops.Op) -> None:
        if not self.lost:
            self.server._backend.send(op)

    async def wait_cancel(self) -> None:
        """Return once a cancel was requested (async handlers)."""
        await self._cancel.wait()

    def request_cancel(self) -> None:
        """The caller asked to cancel this goal (for the actions capability)."""
        self.cancel_requested = True
        self._cancel.set()


class ActionServer(_BridgeHandle):
    """An action served by this client (made by ``ros.advertise_action``; module doc).

    Use as ``await`` or ``async with``; :meth:`unadvertise` (or ``close``) stops serving.
    """

    _backend: ActionBackend

    def __init__(self, backend: ActionBackend, action: str, type_name: str,
                 action_cls: type[Action] | None, handler: ActionHandler, *, id: str) -> None:
        if not callable(handler):
            raise UsageError(f"advertise_action {action}: handler must be callable")
        self._backend = backend
        self.action = action
        self.type_name = type_name
        self.action_cls = action_cls
        self.handler = handler
        self.id = id
        self.closed = False
        self.error: RosLibError | None = None
        self.goals = 0
        """Goals handled."""
        self.failures = 0
        """Goals whose handler raised (aborted)."""
        self.active: dict[str, GoalContext] = {}
        """The goals being served now, by id."""
        self._threads: concurrent.futures.ThreadPoolExecutor | None = None  # plain handlers

    def __repr__(self) -> str:
        return f"<ActionServer {self.action} {self.type_name}{' closed' if self.closed else ''}>"

    def request_op(self) -> ops.AdvertiseAction:
        """The ``advertise_action`` op this server stands for."""
        return ops.AdvertiseAction(self.action, self.type_name, id=self.id)

    async def _ready(self) -> Self:
        try:
            return await super()._ready()  # the bridge's verdict, when it sends one
        except RosLibError:
            self.closed = True
            raise

    async def unadvertise(self) -> None:
        """Stop serving (goals being served are aborted by the bridge)."""
        if self.closed:
            return
        self.closed = True
        self._backend.forget_action(self)
        for ctx in self.active.values():
            ctx.lost = True
            ctx.request_cancel()
        self.stop_threads()

    def stop_threads(self) -> None:
        """Let the handler threads end once their goals return (they saw the cancel);
        goals still waiting for a thread never start."""
        if self._threads is not None:
            self._threads.shutdown(wait=False, cancel_futures=True)
            self._threads = None

    async def close(self) -> None:
        """Same as :meth:`unadvertise`."""
        await self.unadvertise()

    # -- running one goal --

    async def run_goal(self, ctx: GoalContext, args: Any) -> None:
        """Run the handler for one goal and send its result (for the actions capability)."""
        op: ops.ActionResultOp | None = None
        self.goals += 1
        self.active[ctx.id] = ctx
        try:
            goal: Any = dict(args) if isinstance(args, Mapping) else {}
            cls = _part(self.action_cls, "Goal")
            if cls is not None:
                goal = from_wire(goal, cls, f"goal of {self.action}")
            if is_async_callable(self.handler):
                result = await self.handler(goal, ctx)
            else:
                if self._threads is None:
                    self._threads = concurrent.futures.ThreadPoolExecutor(
                        ACTION_HANDLER_THREADS, thread_name_prefix=f"action {self.action}")
                result = await asyncio.get_running_loop().run_in_executor(
                    self._threads, self.handler, goal, ctx)
                if inspect.isawaitable(result):
                    result = await result
            status = GoalStatus.CANCELED if ctx.cancel_requested else GoalStatus.SUCCEEDED
            op = ops.ActionResultOp(id=ctx.id, action=self.action, result=True,
                                  values=self._result_wire(result), status=int(status))
        except asyncio.CancelledError:
            if not ctx.lost:
                raise
        except Exception as exc:
            self.failures += 1
            log.warning("action handler of %s raised %s: %s", self.action,
                        type(exc).__name__, exc)
            op = ops.ActionResultOp(id=ctx.id, action=self.action, result=False,
                                  values=str(exc) or type(exc).__name__,
                                  status=int(GoalStatus.ABORTED))
        finally:
            self.active.pop(ctx.id, None)
            self._backend.served_goal_done(ctx, None if ctx.lost else op)

    def _result_wire(self, result: Any) -> Mapping[str, Any]:
        cls = _part(self.action_cls, "Result")
        if result is None:
            return cls().to_json() if cls is not None else {}
        what = f"result of {self.action}"
        wire = to_wire(result, f"{self.type_name}_Result", cls, what)
        check = cls if cls is not None else (
            _part(_action_class(self.type_name), "Result") if self._backend.validate else None)
        if check is not None and not isinstance(result, Message):
            from_wire(wire, check, what)
        return wire
