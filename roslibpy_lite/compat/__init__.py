"""A drop-in for roslibpy scripts: ``import roslibpy_lite.compat as roslibpy``.

roslibpy 2.1.0's names and signatures over roslibpy_lite (its loop thread and
asyncio client), so a roslibpy script runs by changing only its import::

    import roslibpy_lite.compat as roslibpy

    client = roslibpy.Ros(host="localhost", port=9090)
    client.run()
    talker = roslibpy.Topic(client, "/chatter", "std_msgs/String")
    talker.publish(roslibpy.Message({"data": "Hello World!"}))
    client.terminate()

Covered: :class:`Ros` (host and port or a URL; ``run``, ``run_forever``,
``close``, ``terminate``, ``connect``, ``is_connected``, ``on``/``off``/``emit``
with the ``ready``/``close``/``closing``/``error`` events, ``on_ready``,
``call_later``, ``call_in_thread``, the ``get_*`` introspection calls and
``get_param``/``set_param``/``delete_param``, blocking or with callbacks),
:class:`Topic`, :class:`Message`, :class:`Service`, :class:`ServiceRequest`,
:class:`ServiceResponse`, :class:`ServiceException`, :class:`Param`,
:class:`Time`, :class:`Header` (and ``ros2.Header``), :func:`set_rosapi_timeout`,
:class:`ActionClient` (``send_goal``, ``cancel_goal``, ``wait_goal``) and the
action value classes (:class:`Goal`, :class:`GoalStatus`, :class:`Feedback`,
:class:`Result`).

Not covered: ``headers=`` other than ``Authorization: Bearer``
(raises), ``transport=`` (ignored),
``compression="png"`` (sent as plain JSON), ``authenticate``,
``send_on_ready``, ``blocking_call_from_thread``, ``set_status_level``,
``set_default_transport``, ``roslibpy.tf``, ``roslibpy.actionlib`` (ROS 1).

Differences: every user callback runs on one callback thread of the
``Ros`` (roslibpy: the reactor thread) and may make blocking calls;
errors are roslibpy_lite's (``RosTimeoutError`` is also a ``TimeoutError``).
See docs/compat.md.
"""

from __future__ import annotations

from . import core, ros2
from .core import (
    ActionClient,
    Feedback,
    Goal,
    GoalStatus,
    Header,
    Message,
    Param,
    Result,
    RosTimeoutError,
    Service,
    ServiceException,
    ServiceRequest,
    ServiceResponse,
    Time,
    Topic,
)
from .ros import Ros, set_rosapi_timeout

__version__ = "2.1.0"
"""The roslibpy version whose API this layer follows."""

__all__ = [
    "ActionClient",
    "Feedback",
    "Goal",
    "GoalStatus",
    "Header",
    "Message",
    "Param",
    "Result",
    "Ros",
    "RosTimeoutError",
    "Service",
    "ServiceException",
    "ServiceRequest",
    "ServiceResponse",
    "Time",
    "Topic",
    "core",
    "ros2",
    "set_rosapi_timeout",
]
