"""A robot's big messages, put from a thread of their own: latest wins, whole or not at all.

A camera frame (900 KB) is some 15 Zenoh batches. Put from the event loop with Zenoh's
default congestion control (drop), a frame that finds the link's queue full waits up to
50 ms on the loop and is then dropped in the middle, its first fragments sent for nothing:
through a 2 MB/s uplink no whole frame arrived, and the loop stalled. So a message over
:data:`~.priority.MEDIUM_MESSAGE` bytes (and every later one of its topic, to keep a topic's
order) is handed to :class:`BulkSender`: its thread puts it whole with congestion control
*block*, at the topic's priority (``data_low`` as a rule, below every small message), while
the loop goes on; a newer message of the same topic that comes meanwhile replaces the one
waiting (latest wins, as for any topic put plainly), counted in :attr:`BulkSender.replaced`.
"""

from __future__ import annotations

import contextlib
import logging
import threading
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import zenoh

__all__ = ["BulkSender"]

log = logging.getLogger("bridge_server.zenoh.bulk")


class BulkSender:
    """Puts big messages on ``session`` from a daemon thread, the newest of each key."""

    def __init__(self, session: zenoh.Session) -> None:
        self.session = session
        self.replaced = 0
        """Messages a newer one of their topic replaced before they went out."""
        self._pending: dict[str, tuple[bytes, bytes, dict[str, Any]]] = {}
        self._cond = threading.Condition()
        self._closed = False
        self._thread: threading.Thread | None = None
        """Started at the first big message: a robot that sends none (most of a fleet's
        simulated robots in one process) costs no thread."""

    def put(self, key: str, payload: bytes, attachment: bytes, qos: dict[str, Any]) -> None:
        """Put ``payload`` under ``key`` soon (``qos``: its priority and express), or a newer
        message of ``key`` instead."""
        with self._cond:
            if self._pending.pop(key, None) is not None:
                self.replaced += 1
            self._pending[key] = (payload, attachment, qos)
            self._cond.notify()
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="zenoh-bulk", daemon=True)
            self._thread.start()

    def _run(self) -> None:
        import zenoh

        while True:
            with self._cond:
                self._cond.wait_for(lambda: bool(self._pending) or self._closed)
                if self._closed:
                    return
                key = next(iter(self._pending))
                payload, attachment, qos = self._pending.pop(key)
            try:
                self.session.put(key, payload, attachment=attachment,
                                 congestion_control=zenoh.CongestionControl.BLOCK, **qos)
            except zenoh.ZError as exc:  # the session closed under it
                log.debug("a message of %d bytes for %s was not sent: %s", len(payload), key,
                          exc)

    def close(self) -> None:
        """Stop the thread (what waits is not sent)."""
        with self._cond:
            self._closed = True
            self._pending.clear()
            self._cond.notify()
        if self._thread is not None:
            with contextlib.suppress(RuntimeError):
                self._thread.join(timeout=1.0)
