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

from rosbridge_core.protocol.goal_status import GoalStatus

from .goals import ActionError, ActionResult, FeedbackCallback, GoalHandle, action_type
from .goals import _action_class as _action_class
from .goals import _part as _part
from .serving import ACTION_HANDLER_THREADS as ACTION_HANDLER_THREADS
from .serving import ActionBackend as ActionBackend
from .serving import ActionHandler, ActionServer, GoalContext

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
