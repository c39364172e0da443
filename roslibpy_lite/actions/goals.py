"""Sending goals (:class:`GoalHandle`) and what a goal ends with (:class:`ActionResult`,
:class:`ActionError`), the action type a name or class stands for (:func:`action_type`), and
what a sent goal needs from the actions capability (:class:`GoalBackend`; a served action's
needs add to it: :class:`~roslibpy_lite.actions.serving.ActionBackend`)."""

from __future__ import annotations

import asyncio
import collections
import inspect
import logging
from collections.abc import AsyncIterator, Awaitable, Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol, cast

from msgs.runtime import Action, Message, UnknownTypeError, lookup_action
from rosbridge_core.protocol import ops
from rosbridge_core.protocol.goal_status import GoalStatus

from ..exceptions import (
    ConnectionClosed,
    InvalidMessageError,
    RemoteError,
    RosLibError,
    RosTimeoutError,
    UsageError,
)
from ..handles.base import Backend
from ..messages import _check_type_string, _packages, canonical_type, from_wire

if TYPE_CHECKING:
    from collections.abc import Coroutine

log = logging.getLogger("roslibpy_lite.client")

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

class GoalBackend(Backend, Protocol):
    """What a sent goal needs from the capability that made it
    (:class:`~roslibpy_lite.capabilities.actions.Actions`)."""

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


class GoalHandle:
    """A goal this client sent (made by ``await ros.send_goal(...)``; module doc).

    Iterate it (``async for fb in goal``) or :meth:`feedback` for its
    feedback until it ends; ``await`` :meth:`result`; :meth:`cancel` it.
    """

    def __init__(self, backend: GoalBackend, action: str, type_name: str,
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


