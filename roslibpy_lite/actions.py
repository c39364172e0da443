"""ROS 2 actions on the client: send goals to action servers, and serve actions.

Sending a goal::

    goal = await ros.send_goal("/integrate_imu", "mult_msgs/action/IntegrateImu",
                               {"seconds": 2.0})
    async for fb in goal:                 # feedback until the goal ends
        print(fb["sum"])
    outcome = await goal.result(timeout=10)
    print(outcome.status, outcome.values)  # GoalStatus.SUCCEEDED {'total': ..., ...}

The outcome rules
-----------------
- :meth:`GoalHandle.result` returns an :class:`ActionResult` (``status``, a
  :class:`GoalStatus`, and ``values``: the result as a dict, or the
  ``Result`` instance of a typed action) for every goal the action server
  ran to an end: succeeded, canceled, or aborted by the server.
  ``result(raise_on_failure=True)`` raises :class:`ActionError` unless it
  succeeded.
- A goal that never ran raises :class:`ActionError` (status ``ABORTED``)
  naming why: no such action server, an unknown action type, a goal that does
  not fit the type (also caught here before sending, as
  :class:`~roslibpy_lite.exceptions.InvalidMessageError`), the server rejected
  it, or the bridge's goal timeout.
- A dropped connection fails every goal in flight at once with
  :class:`~roslibpy_lite.exceptions.Disconnected` (the bridge cancels them on
  the ROS side); closing the client with
  :class:`~roslibpy_lite.exceptions.ConnectionClosed`.
- ``result(timeout=...)`` raises :class:`~roslibpy_lite.exceptions.RosTimeoutError`
  when the goal has not ended in time; the goal goes on (``await goal.cancel()``
  to stop it).

``goal.status`` is ``UNKNOWN`` until the server shows it took the goal
(``ACCEPTED`` when our bridge reports the acceptance, ``EXECUTING`` at the
first feedback; :meth:`GoalHandle.accepted` waits for either), ``CANCELING``
after :meth:`GoalHandle.cancel`, and the final status once the result came.

Serving an action::

    async def integrate(goal, ctx):
        total = 0.0
        for _ in range(int(goal["seconds"] * 10)):
            if ctx.cancel_requested:
                break                     # returning after a cancel: CANCELED
            total += 0.1
            ctx.publish_feedback({"sum": {"x": total}, "elapsed": ...})
            await asyncio.sleep(0.1)
        return {"total": {"x": total}, "samples": 10}

    server = await ros.advertise_action("/integrate_imu", "mult_msgs/action/IntegrateImu",
                                        integrate)

The handler gets the goal (a dict, or the ``Goal`` instance of a typed
action) and a :class:`GoalContext`, and returns the result (dict, ``Result``
instance, or None for the default). An async handler runs as a task on the
loop; a sync one runs in a worker thread of the action server's own (up to
``ACTION_HANDLER_THREADS`` goals at once, more wait; goals can run for minutes,
so they never hold the loop's default executor, which name lookups for a
reconnect need). ``ctx.publish_feedback`` and ``ctx.cancel_requested`` work
from there. A handler that raises aborts the
goal, and the error's text is logged and sent to the bridge. A handler that
returns after a cancel request ends the goal ``CANCELED``. Served actions are
advertised again after every reconnect; goals being served when the
connection drops are aborted by the bridge, and their handlers are cancelled
(async) or see ``cancel_requested`` (sync).
"""

from __future__ import annotations

import asyncio
import collections
import concurrent.futures
import inspect
import logging
from collections.abc import AsyncIterator, Awaitable, Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol, Self, cast

from msgs.runtime import Action, Message, UnknownTypeError, lookup_action
from rosbridge_core.protocol import ops
from rosbridge_core.protocol.goal_status import GoalStatus

from ._aio import is_async_callable, running_loop
from .exceptions import (
    ConnectionClosed,
    InvalidMessageError,
    RemoteError,
    RosLibError,
    RosTimeoutError,
    UsageError,
)
from .handles.base import Backend, _BridgeHandle
from .messages import _check_type_string, _packages, canonical_type, check_dict, from_wire, to_wire

if TYPE_CHECKING:
    from collections.abc import Coroutine

__all__ = [
    "ActionError",
    "ActionHandler",
    "ActionResult",
    "ActionServer",
    "FeedbackCallback",
    "GoalContext",
    "GoalHandle",
    "GoalStatus",
    "action_type",
]

log = logging.getLogger("roslibpy_lite.client")

ACTION_HANDLER_THREADS = 32
"""Goals one action server runs at once with a plain (not ``async``) handler; more wait."""

ActionHandler = Callable[[Any, "GoalContext"], Any]
"""An action handler: ``fn(goal, ctx) -> result``, sync (run in a thread) or ``async``."""

FeedbackCallback = Callable[[Any], "Awaitable[None] | None"]
"""Called with each feedback of a goal: ``fn(feedback)``, sync or ``async``."""


@dataclass(frozen=True, slots=True)
class ActionResult:
    """How a goal ended: its final ``status`` and the result ``values``.

    ``values`` is a dict (or the ``Result`` instance of a typed action); it
    is None only when the bridge had no result to give (``text`` then says why).
    """

    status: GoalStatus
    values: Any
    text: str | None = None

    @property
    def succeeded(self) -> bool:
        """True when the status is SUCCEEDED."""
        return self.status is GoalStatus.SUCCEEDED


class ActionError(RemoteError):
    """A goal failed: it never ran (the text says why), or with ``raise_on_failure``
    it ended CANCELED or ABORTED. ``status`` is the final :class:`GoalStatus`,
    ``values`` the result values when there were any."""

    def __init__(self, action: str, reason: str, status: GoalStatus = GoalStatus.ABORTED,
                 values: Any = None) -> None:
        mentioned = action in reason or "/" + action.lstrip("/") in reason
        super().__init__(reason if mentioned else f"goal to {action}: {reason}")
        self.action = action
        self.reason = reason
        self.status = status
        self.values = values


def action_type(type_: str | type[Action]) -> tuple[str, type[Action] | None]:
    """The canonical type name and (for a generated class) the class of an action type.

    Raises:
        UsageError: a malformed name, a name ``msgs`` should know but does not,
            or a class that is not an action.
    """
    if isinstance(type_, str):
        _check_type_string(type_, "action")
        name = canonical_type(type_, "action")
        if name.split("/", 1)[0] in _packages():
            try:
                lookup_action(name)
            except UnknownTypeError as exc:
                raise UsageError(f"unknown action type {name!r}: {exc}") from None
        return name, None
    if isinstance(type_, type) and issubclass(type_, Action):
        return type_._type, type_
    raise UsageError(f"an action type must be a type string or a msgs action class, got {type_!r}")


def _action_class(type_name: str) -> type[Action] | None:
    try:
        return lookup_action(type_name)
    except UnknownTypeError:
        return None


def _part(cls: type[Action] | None, part: str) -> type[Message] | None:
    return cast("type[Message]", getattr(cls, part)) if cls is not None else None


# --- sending goals ---------------------------------------------------------------------------

class ActionBackend(Backend, Protocol):
    """What goals and served actions need from the capability that made them
    (:class:`~roslibpy_lite.capabilities.actions.Actions`)."""

    @property
    def validate(self) -> bool:
        """Whether dicts are checked against their type's ``msgs`` class."""
        ...

    def send(self, op: ops.Op) -> None:
        """Send an op (dropped while disconnected)."""
        ...

    async def flush(self) -> None:
        """Return once everything sent so far is handed to the connection."""
        ...

    def spawn(self, coro: Coroutine[Any, Any, None]) -> None:
        """Run a callback's task (cancelled when the client closes)."""
        ...

    def goal_ended(self, goal: GoalHandle) -> None:
        """A sent goal ended (or failed)."""
        ...

    def forget_action(self, server: ActionServer) -> None:
        """Forget a served action and tell the bridge."""
        ...

    def served_goal_done(self, ctx: GoalContext, op: ops.ActionResultOp | None) -> None:
        """A served goal's handler returned: send ``op`` (None: the goal was lost)."""
        ...


class GoalHandle:
    """A goal this client sent (made by ``await ros.send_goal(...)``; module doc).

    Iterate it (``async for fb in goal``) or :meth:`feedback` for its
    feedback until it ends; ``await`` :meth:`result`; :meth:`cancel` it.
    """

    def __init__(self, backend: ActionBackend, action: str, type_name: str,
                 action_cls: type[Action] | None, id: str, *, buffer_size: int,
                 on_feedback: FeedbackCallback | None) -> None:
        self._backend = backend
        self.action = action
        self.type_name = type_name
        self.action_cls = action_cls
        self.id = id
        self.status = GoalStatus.UNKNOWN
        self.error: RosLibError | None = None
        self.closed = False
        self.last_feedback: Any = None
        """The newest feedback (None before the first)."""
        self.dropped = 0
        """Feedback dropped because the buffer was full (the oldest goes first)."""
        self._buffer: collections.deque[Any] = collections.deque(maxlen=max(buffer_size, 1))
        self._wake = asyncio.Event()
        self._done: asyncio.Future[ActionResult] = asyncio.get_running_loop().create_future()
        self._done.add_done_callback(_consume)
        self._on_feedback = on_feedback
        self._known_accepted = asyncio.Event()

    def __repr__(self) -> str:
        return f"<GoalHandle {self.action} {self.id} {self.status.name}>"

    def done(self) -> bool:
        """True once the goal has ended (or failed)."""
        return self._done.done()

    # -- from the capability --

    def confirmed(self) -> None:
        """The bridge says the action server accepted the goal (for the actions capability)."""
        if self.status is GoalStatus.UNKNOWN:
            self.status = GoalStatus.ACCEPTED
        self._known_accepted.set()

    def feedback_arrived(self, values: Any) -> None:
        """One feedback message for this goal arrived (for the actions capability)."""
        if self.done():
            return
        self._known_accepted.set()  # feedback comes only from a goal that runs
        if self.status is GoalStatus.UNKNOWN or self.status is GoalStatus.ACCEPTED:
            self.status = GoalStatus.EXECUTING
        fb = values
        cls = _part(self.action_cls, "Feedback")
        if cls is not None and isinstance(values, Mapping):
            try:
                fb = from_wire(values, cls, f"feedback of {self.action}")
            except InvalidMessageError as exc:
                log.warning("%s", exc)
                return
        self.last_feedback = fb
        if len(self._buffer) == self._buffer.maxlen:
            self.dropped += 1
        self._buffer.append(fb)
        self._wake.set()
        cb = self._on_feedback
        if cb is not None:
            try:
                out = cb(fb)
                if inspect.isawaitable(out):
                    self._backend.spawn(_awaited_callback(out, self.action))
            except Exception:
                log.exception("feedback callback of %s raised", self.action)

    def result_arrived(self, op: ops.ActionResultOp) -> None:
        """The goal's result arrived (for the actions capability)."""
        if self.done():
            return
        try:
            status = GoalStatus(op.status) if op.status is not None else None
        except ValueError:
            status = None
        if status is None or not status.final:
            status = GoalStatus.SUCCEEDED if op.result else GoalStatus.ABORTED
        if not op.result and status is GoalStatus.SUCCEEDED:
            status = GoalStatus.ABORTED
        values: Any = op.values
        if isinstance(values, str) or values is None:
            text = values or "the action server gave no result"
            if status is GoalStatus.CANCELED:
                self._end(ActionResult(status, None, text))
            else:
                self.fail(ActionError(self.action, text, status))
            return
        cls = _part(self.action_cls, "Result")
        if cls is not None:
            try:
                values = from_wire(values, cls, f"result of {self.action}")
            except InvalidMessageError as exc:
                self.fail(ActionError(self.action, str(exc), GoalStatus.ABORTED))
                return
        else:
            values = dict(values)
        self._end(ActionResult(status, values))

    def _end(self, outcome: ActionResult) -> None:
        self.status = outcome.status
        self._done.set_result(outcome)
        self._finished()

    def fail(self, error: RosLibError) -> None:
        """The goal failed (a status error naming it, a failed result, a dropped connection)."""
        if self.done():
            return
        if not isinstance(error, ActionError | ConnectionClosed):
            error = ActionError(self.action, str(error))
        self.error = error
        self.status = error.status if isinstance(error, ActionError) else GoalStatus.ABORTED
        self._done.set_exception(error)
        self._finished()

    def _finished(self) -> None:
        self.closed = True
        self._wake.set()
        self._known_accepted.set()  # accepted() looks at how it ended
        self._backend.goal_ended(self)

    # -- the user's side --

    async def result(self, timeout: float | None = None, *,
                     raise_on_failure: bool = False) -> ActionResult:
        """Wait for the goal to end and return how it ended (module doc: the outcome rules).

        Raises:
            ActionError: the goal never ran; or (``raise_on_failure``) it did not succeed.
            RosTimeoutError: not ended within ``timeout`` seconds (the goal goes on).
            Disconnected: the connection dropped while the goal was in flight.
            ConnectionClosed: the client was closed.
        """
        try:
            async with asyncio.timeout(timeout):
                outcome = await asyncio.shield(self._done)
        except TimeoutError:
            raise RosTimeoutError(
                f"goal to {self.action}: no result within {timeout} s "
                f"(status {self.status.name}; the goal goes on)"
            ) from None
        if raise_on_failure and not outcome.succeeded:
            raise ActionError(self.action, f"the goal ended {outcome.status.name}"
                              + (f": {outcome.text}" if outcome.text else ""),
                              outcome.status, outcome.values)
        return outcome

    async def accepted(self, timeout: float | None = None) -> None:
        """Return once the action server is known to have accepted the goal.

        Our bridge says so as soon as the server accepts; a stock rosbridge says nothing,
        so there the first feedback or the goal's result shows it.

        Raises:
            ActionError: the goal never ran (refused by the bridge, rejected by the
                server, no such action, ...).
            RosTimeoutError: not known to be accepted within ``timeout`` seconds.
            Disconnected / ConnectionClosed: the connection went first.
        """
        try:
            async with asyncio.timeout(timeout):
                await self._known_accepted.wait()
        except TimeoutError:
            raise RosTimeoutError(f"goal to {self.action}: not accepted within {timeout} s "
                                  f"(status {self.status.name})") from None
        if self.error is not None:
            raise self.error

    async def cancel(self) -> None:
        """Ask the action server to cancel the goal (its result follows); harmless once ended."""
        if self.done():
            return
        self.status = GoalStatus.CANCELING
        self._backend.send(ops.CancelActionGoal(id=self.id, action=self.action))
        await self._backend.flush()

    async def feedback(self) -> AsyncIterator[Any]:
        """Each feedback (dict, or ``Feedback`` instance) until the goal ends."""
        while True:
            try:
                yield await self._next_feedback()
            except StopAsyncIteration:
                return

    async def _next_feedback(self) -> Any:
        """The next feedback; StopAsyncIteration once the goal has ended and none is left.

        Cancelling it (a timeout, Ctrl+C in the blocking client) loses nothing and
        ends nothing: a later call goes on with the next feedback. Several readers
        may wait at once; each feedback goes to one of them.
        """
        while not self._buffer:
            if self.done():
                raise StopAsyncIteration
            self._wake.clear()
            await self._wake.wait()
        return self._buffer.popleft()

    def __aiter__(self) -> AsyncIterator[Any]:
        return self.feedback()


def _consume(future: asyncio.Future[Any]) -> None:
    """Mark a goal's exception as seen (a goal nobody awaits must not log "never retrieved")."""
    if not future.cancelled():
        future.exception()


async def _awaited_callback(awaitable: Awaitable[Any], action: str) -> None:
    try:
        await awaitable
    except Exception:
        log.exception("feedback callback of %s raised", action)


# --- serving actions -------------------------------------------------------------------------

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
