"""What the bag modules share: the optional ``mcap`` dependency and ROS 2's MCAP names."""

from __future__ import annotations

from ..exceptions import UsageError

#: The MCAP profile, schema encoding and message encoding rosbag2 writes.
ROS2_PROFILE = "ros2"
SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"


def need_mcap() -> None:
    """Raise a UsageError naming the extra to install when ``mcap`` is missing."""
    try:
        import mcap  # noqa: F401
    except ImportError:
        raise UsageError("recording and playing MCAP files needs the mcap library: "
                         "pip install 'roslibpy-lite[mcap]'") from None
