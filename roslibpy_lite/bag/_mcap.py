"""What the bag modules share: the optional ``mcap`` dependency and ROS 2's MCAP names."""

from __future__ import annotations

import re
from typing import Any

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
        raise UsageError(MISSING) from None


MISSING = "the mcap extra is not installed: pip install 'roslibpy-lite[mcap]'"
"""What is said when the ``mcap`` library is missing, and only that."""


def format_size(n: float) -> str:
    """A byte count as people read it, in powers of 1000 as file managers show them:
    ``512 B``, ``18.5 kB``, ``3.2 MB``, ``1.5 GB``."""
    if n < 1000:
        return f"{int(n)} B"
    for unit in ("kB", "MB", "GB"):
        n /= 1000
        if n < 999.95 or unit == "GB":  # what rounds to 1000 goes up a unit
            return f"{n:.1f} {unit}"
    raise AssertionError("unreachable")


def qos_yaml(profiles: list[dict[str, Any]]) -> str:
    """rosbag2's ``offered_qos_profiles`` channel metadata: a YAML list of QoS profiles
    (keys and words as rosbag2 9+ writes them), from ``/rosapi/publishers_qos``'s ``qos``."""
    lines: list[str] = []
    for profile in profiles:
        lead = "- "
        for key, value in profile.items():
            if isinstance(value, dict):
                lines.append(f"{lead}{key}:")
                lines.extend(f"    {k}: {_scalar(v)}" for k, v in value.items())
            else:
                lines.append(f"{lead}{key}: {_scalar(value)}")
            lead = "  "
    return "\n".join(lines) if lines else "[]"


def _scalar(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int) or (isinstance(value, str) and _PLAIN.fullmatch(value)):
        return str(value)
    raise UsageError(f"offered_qos_profiles: unexpected value {value!r}")


_PLAIN = re.compile(r"[a-z_]+")
