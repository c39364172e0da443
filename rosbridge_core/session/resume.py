"""Sessions that outlive their connection (our extension; stock clients never see it).

A client that sends ``X-Rosbridge-Session: new``
(:data:`~rosbridge_core.protocol.ops.SESSION_HEADER`) gets a session token back. When its link
drops, the bridge keeps the session
(subscriptions with their bounded queues, publishers, served services and
actions, the frames it wrote that the client has not confirmed) for
``session_keep`` seconds. A client that reconnects with the token and the number of
frames it received (:data:`~rosbridge_core.protocol.ops.RECEIVED_HEADER`) gets the session back:
the bridge answers with the number of frames it received, and each side sends
again what the other missed. Both sides confirm what they received with a
``session_ack`` op every :data:`ACK_INTERVAL` seconds, so each keeps only what
is in flight.

Limits: ``session_keep`` seconds (0 turns sessions off), at most
``sessions_per_principal`` kept sessions per principal (the oldest goes first),
and at most ``resume_frames`` frames / ``resume_bytes`` bytes kept per session
for sending again (older ones are dropped, and the client hears how many it
missed). A session belongs to the principal that opened it: resuming needs the
same principal at the handshake (a header or query token), and the token, 128
random bits, is never logged.

With ``--workers`` a session lives in the worker that opened it, and its token starts with
that worker's index (``w1.`` and the random part): a worker that a resume reaches for
another worker's token hands the connection over to it (:mod:`bridge_server.front.forward`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import re
import secrets
from collections import deque
from dataclasses import dataclass
from typing import TYPE_CHECKING, Generic, Protocol, TypeVar

if TYPE_CHECKING:
    from rosbridge_core.security.gate import Gate
    from rosbridge_core.session.link import ClientLink

__all__ = ["ACK_INTERVAL", "Keepable", "ResumeConfig", "SentFrames", "SessionStore", "worker_of"]

log = logging.getLogger("bridge_server.session.resume")

ACK_INTERVAL = 0.25
"""Seconds between a side's ``session_ack`` ops while frames arrive."""

CLAIM_WAIT = 3.0
"""Seconds a resume waits for the session's old connection to be given up."""


@dataclass
class ResumeConfig:
    """How long and how much of a dropped client's session the bridge keeps."""

    session_keep: float = 30.0
    sessions_per_principal: int = 4
    resume_frames: int = 1000
    resume_bytes: int = 8 * 1024 * 1024


class SentFrames:
    """The frames one session wrote that its client has not confirmed, numbered from 1."""

    def __init__(self, max_frames: int, max_bytes: int) -> None:
        self.max_frames = max_frames
        self.max_bytes = max_bytes
        self.frames: deque[str | bytes] = deque()
        self.first = 1  # the number of frames[0]
        self.count = 0  # frames written in this session
        self.size = 0

    def add(self, frame: str | bytes) -> None:
        """One more frame written."""
        self.count += 1
        self.frames.append(frame)
        self.size += len(frame)
        while self.frames and (len(self.frames) > self.max_frames or self.size > self.max_bytes):
            self.size -= len(self.frames.popleft())
            self.first += 1

    def acked(self, count: int) -> None:
        """The client has received ``count`` frames: forget those."""
        frames = self.frames
        while frames and self.first <= count:
            self.size -= len(frames.popleft())
            self.first += 1

    def since(self, count: int) -> tuple[list[str | bytes], int]:
        """The frames after the client's ``count`` (to send again) and how many of those are
        no longer kept; numbering then goes on from ``count``."""
        self.acked(count)
        missing = max(0, self.first - count - 1)
        again = list(self.frames)
        self.frames.clear()
        self.first = count + 1
        self.count = count
        self.size = 0
        return again, missing


_WORKER_PREFIX = re.compile(r"w([0-9]{1,4})\.")


def worker_of(token: str) -> int | None:
    """The index of the worker that keeps the session ``token`` names (``None``: the token
    names no worker, as without ``--workers``)."""
    match = _WORKER_PREFIX.match(token)
    return None if match is None else int(match[1])


class Keepable(Protocol):
    """A session the store can keep for a resume
    (:class:`~rosbridge_core.session.session.Session`)."""

    sid: int
    gate: Gate
    link: ClientLink

    def end_parked(self) -> None:
        """The kept session was not resumed in time: release what it owned."""


S = TypeVar("S", bound=Keepable)


class SessionStore(Generic[S]):
    """The sessions that can be resumed, by token; the dropped ones wait here."""

    def __init__(self, config: ResumeConfig, worker: int | None = None) -> None:
        """``worker``: this worker's index, named in its tokens (``None``: no workers)."""
        self.config = config
        self.prefix = "" if worker is None else f"w{worker}."
        self.live: dict[str, S] = {}
        self.parked: dict[str, asyncio.TimerHandle] = {}
        self._parked_event: dict[str, asyncio.Event] = {}
        self.resumed = 0
        self.expired = 0
        self.closing = False  # the bridge stops: no session is kept any more

    @property
    def enabled(self) -> bool:
        """Whether this bridge keeps sessions at all."""
        return self.config.session_keep > 0

    def new_token(self) -> str:
        """A fresh session token (not yet bound to a session)."""
        return self.prefix + secrets.token_urlsafe(16)

    def register(self, token: str, session: S) -> None:
        """``session`` (just opened) can be resumed with ``token``."""
        self.live[token] = session

    async def claim(self, token: str, principal: object) -> S | None:
        """The session ``token`` names, given up by its old connection and held for the new
        one; None if there is none (expired, unknown) or it belongs to another principal."""
        session = self.live.get(token)
        if session is None or session.gate.principal is not principal:
            return None
        if token not in self.parked:  # its old link is dead but not noticed yet: give it up
            event = self._parked_event.setdefault(token, asyncio.Event())
            session.link.abort()
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(CLAIM_WAIT):  # keeps a cancel (3.11's wait_for may not)
                    await event.wait()
        timer = self.parked.pop(token, None)
        if timer is None or self.live.get(token) is not session:
            return None
        timer.cancel()
        self.resumed += 1
        return session

    def park(self, token: str, session: S) -> bool:
        """``session`` lost its connection: keep it for ``session_keep`` s (False: it may not
        be kept, and ends now)."""
        if self.live.get(token) is not session or self.closing:
            self.live.pop(token, None)
            return False
        mine = [t for t, s in self.live.items()
                if t in self.parked and s.gate.principal is session.gate.principal]
        while len(mine) >= self.config.sessions_per_principal:  # the oldest goes first
            self.drop(mine.pop(0), "too many kept sessions for its principal")
        loop = asyncio.get_running_loop()
        self.parked[token] = loop.call_later(self.config.session_keep, self.drop, token,
                                             f"not resumed within {self.config.session_keep:g} s")
        event = self._parked_event.pop(token, None)
        if event is not None:
            event.set()
        return True

    def drop(self, token: str, why: str) -> None:
        """End a kept session now."""
        timer = self.parked.pop(token, None)
        session = self.live.pop(token, None)
        if timer is not None:
            timer.cancel()
        if session is not None:
            self.expired += 1
            log.info("client %d: session ended (%s)", session.sid, why)
            session.end_parked()

    def forget(self, token: str, session: S) -> None:
        """``session`` ended for good (closed by the client, or not resumable)."""
        if self.live.get(token) is session:
            del self.live[token]
        timer = self.parked.pop(token, None)
        if timer is not None:
            timer.cancel()

    def close(self) -> None:
        """The bridge stops: end every kept session, and keep none from now on."""
        self.closing = True
        for token in list(self.parked):
            self.drop(token, "the bridge stopped")
