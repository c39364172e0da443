"""roslibpy_lite: a fast, dependable asyncio client for ROS 2 over rosbridge v2.

Needs only ``websockets``; no ROS installation.
"""

from __future__ import annotations

__version__ = "0.1.0"
