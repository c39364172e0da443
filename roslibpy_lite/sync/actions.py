"""Blocking action handles: a goal sent (:class:`GoalHandle`) and an action served.

Made by :meth:`roslibpy_lite.sync.Client.send_goal` and
:meth:`~roslibpy_lite.sync.Client.advertise_action`; the rules are those of
:mod:`roslibpy_lite.actions` (outcomes, errors, cancel), without ``await``.
"""

from __future__ import annotations

import asyncio
from collections.abc import Iterator
from typing import Any

from .. import actions
from ..exceptions import RosTimeoutError
from .handles import _BlockingHandle, _Wrapper

__all__ = ["ActionServer", "GoalHandle"]


class GoalHandle(_Wrapper[actions.GoalHandle]):
    """A goal this client sent: iterate its feedback, :meth:`result`, :meth:`cancel`."""

    @property
    def id(self) -> str:
        """The goal's request id."""
        return self.handle.id

    @property
    def status(self) -> actions.GoalStatus:
        """The goal's status as known here (see :mod:`roslibpy_lite.actions`)."""
        return self.handle.status

    def done(self) -> bool:
        """True once the goal has ended."""
        return self.handle.done()

    def result(self, timeout: float | None = None, *,
               raise_on_failure: bool = False) -> actions.ActionResult:
        """Wait for the goal to end; its :class:`~roslibpy_lite.actions.ActionResult`.

        Raises ActionError, RosTimeoutError (the goal goes on), Disconnected,
        ConnectionClosed, as :meth:`roslibpy_lite.actions.GoalHandle.result` does.
        """
        return self._loop.run(self.handle.result(timeout, raise_on_failure=raise_on_failure),
                              f"result of {self.handle.action}")

    def accepted(self, timeout: float | None = None) -> None:
        """Return once the action server is known to have accepted the goal (as
        :meth:`roslibpy_lite.actions.GoalHandle.accepted`, with its exceptions)."""
        self._loop.run(self.handle.accepted(timeout), f"goal to {self.handle.action}")

    def cancel(self) -> None:
        """Ask the action server to cancel the goal (its result follows)."""
        self._loop.run(self.handle.cancel(), f"cancel goal to {self.handle.action}")

    def feedback(self, timeout: float | None = None) -> Iterator[Any]:
        """Each feedback until the goal ends.

        After a ``RosTimeoutError`` (or Ctrl+C) the goal goes on, and calling
        ``feedback()`` again continues with the next feedback. Several threads may
        iterate at once; each feedback goes to one of them.

        Raises:
            RosTimeoutError: none within ``timeout`` seconds of the previous one.
        """
        while True:
            try:
                yield self._loop.run(self._next(timeout), f"feedback of {self.handle.action}")
            except StopAsyncIteration:
                return

    async def _next(self, timeout: float | None) -> Any:
        try:
            async with asyncio.timeout(timeout):
                return await self.handle._next_feedback()
        except TimeoutError:
            raise RosTimeoutError(
                f"no feedback from {self.handle.action} within {timeout} s") from None

    def __iter__(self) -> Iterator[Any]:
        return self.feedback()


class ActionServer(_BlockingHandle[actions.ActionServer]):
    """A blocking action server: ``with`` it, or :meth:`unadvertise` (``close``)."""

    @property
    def action(self) -> str:
        """The action name."""
        return self.handle.action

    def unadvertise(self) -> None:
        """Stop serving."""
        self.close()
