"""A goal's status: the numbers of ``action_msgs/msg/GoalStatus`` as an enum.

They travel in the ``action_result`` op's ``status`` field; the client reports them
(``roslibpy_lite.GoalStatus``) and the bridge gives them to ROS (an ``IntEnum``, so rclpy
takes its members as the numbers they are).
"""

from __future__ import annotations

import enum

__all__ = ["GoalStatus"]


class GoalStatus(enum.IntEnum):
    """The status of a goal: the numbers of ``action_msgs/msg/GoalStatus``.

    It equals its number (``GoalStatus.SUCCEEDED == 4``) and prints as its name
    (``print(result.status)`` shows ``SUCCEEDED``).
    """

    UNKNOWN = 0
    ACCEPTED = 1
    EXECUTING = 2
    CANCELING = 3
    SUCCEEDED = 4
    CANCELED = 5
    ABORTED = 6

    def __str__(self) -> str:
        return self.name

    def __format__(self, spec: str) -> str:
        return format(self.name, spec) if not spec or spec[-1] not in "dxXobn" else \
            format(int(self), spec)

    @property
    def final(self) -> bool:
        """True for SUCCEEDED, CANCELED and ABORTED."""
        return self >= GoalStatus.SUCCEEDED
