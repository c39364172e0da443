"""The keepalive every client connection of the bridge runs, whatever protocol it speaks.

Where TCP tells when the peer was last heard
(:func:`roslibpy_lite.protocol.keepalive.supported_here`), a session watches its link itself
(:func:`roslibpy_lite.protocol.keepalive.watch`: a silent client is pinged, and dropped with what
it owned only if it then answers nothing within the timeout);
elsewhere the bridge leaves websockets' own ping keepalive on, with the same figures.
"""

from __future__ import annotations

import asyncio
import logging
from typing import Any

from roslibpy_lite.protocol import keepalive

__all__ = ["watch_link"]

log = logging.getLogger("bridge_server.session")


def watch_link(ws: Any, sid: int, interval: float, timeout: float) -> asyncio.Task[bool] | None:
    """Start watching client ``sid``'s connection ``ws`` (``interval`` 0: no keepalive of our
    own); ``None`` where it cannot be watched. Cancel the task when the connection ends."""
    transport = getattr(ws, "transport", None)
    if not interval or transport is None or not keepalive.supported_here():
        return None

    def dead(silence: float) -> None:
        log.warning("client %d: no sign of it for %.1f s, nor an answer to a ping (a silent "
                    "link): dropping it and what it owned", sid, silence)

    return asyncio.create_task(keepalive.watch(transport, ws.ping, dead, interval, timeout),
                               name=f"session-{sid}-keepalive")
