"""``roslibpy.ros2``: the ROS 2 message header."""

from __future__ import annotations

from collections.abc import Mapping

from .core import Header as _Ros1Header
from .core import Time

__all__ = ["Header"]


class Header(_Ros1Header):
    """A ROS 2 ``std_msgs/msg/Header`` (stamp, frame_id; no seq)."""

    def __init__(self, stamp: Mapping[str, int] | None = None, frame_id: str | None = None) -> None:
        super().__init__(stamp=stamp, frame_id=frame_id)
        self.data["stamp"] = Time(stamp["secs"], stamp["nsecs"]) if stamp else None
        del self.data["seq"]
