"""What carries ops between the client (:mod:`roslibpy_lite.ros`) and a bridge.

:class:`~roslibpy_lite.transports.base.Transport` is the seam: ops in, ops
out, connection events up. :mod:`.websocket` speaks to a real bridge;
:mod:`.memory` plays the bridge's part in memory (under
:class:`~roslibpy_lite.mock.MockRos`).
"""

from __future__ import annotations

from .base import Link, Transport

__all__ = ["Link", "Transport"]
