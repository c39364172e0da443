"""QoS profiles of the bridge's ROS entities (topics, services and actions alike)."""

from __future__ import annotations

from typing import Any

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

__all__ = ["SERVICE_DEPTH", "qos_profile"]

SERVICE_DEPTH = 1000
"""History depth of the bridge's service clients and servers: the ROS default of 10 loses
requests and responses when more than 10 calls are in flight."""


def qos_profile(reliable: bool, transient_local: bool, depth: int) -> Any:
    """A keep-last profile of ``depth``: reliable or best effort, transient local or volatile."""
    return QoSProfile(  # type: ignore[no-untyped-call]
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=(
            DurabilityPolicy.TRANSIENT_LOCAL if transient_local else DurabilityPolicy.VOLATILE
        ),
    )
