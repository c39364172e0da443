"""The keepalive every client connection of the bridge runs, whatever protocol it speaks.

Where TCP tells when the peer was last heard
(:func:`rosbridge_core.protocol.keepalive.supported_here`), a session watches its link itself
(:func:`rosbridge_core.protocol.keepalive.watch`: a silent client is pinged, and dropped with what
it owned only if it then answers nothing within the timeout);
elsewhere the bridge leaves websockets' own ping keepalive on, with the same figures.
"""

from __future__ import annotations

import asyncio
import logging
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rosbridge_core.session.link import ClientLink, LinkConfig

__all__ = ["watch_link"]

log = logging.getLogger("bridge_server.session")


def watch_link(link: ClientLink, sid: int, config: LinkConfig) -> asyncio.Task[bool] | None:
    """Start watching client ``sid``'s ``link`` (``config.keepalive_interval`` 0: no keepalive
    of our own); ``None`` where it cannot be watched. Cancel the task when the link ends."""

    def dead(silence: float) -> None:
        log.warning("client %d: no sign of it for %.1f s, nor an answer to a ping (a silent "
                    "link): dropping it and what it owned", sid, silence)

    return link.watch(config.keepalive_interval, config.keepalive_timeout, dead)
