"""The client's half of sessions that outlive a dropped link (our bridge's extension).

On the first connection the client asks for a session (``X-Rosbridge-Session: new``);
our bridge answers with a token, stock servers answer nothing and then nothing
here applies. Both sides count the frames they receive in the session (every
frame but ``session_ack``) and confirm the count every so often with a
``session_ack`` op; each keeps what it wrote until the other confirms it. After a
dropped link the client reconnects with its token and its count; if the bridge
still keeps the session it answers with its own count, and each side writes
again, in order, what the other did not receive: nothing the client accepted is
lost or published twice, and messages that arrived on the robot meanwhile are
delivered (within each subscription's queue bound).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping

from rosbridge_core.protocol.ops import RECEIVED_HEADER, SESSION_HEADER, parse_received

__all__ = ["ACK_INTERVAL", "ClientSession"]

ACK_INTERVAL = 0.25
"""Seconds between the client's ``session_ack`` ops while frames arrive."""


class ClientSession:
    """Counts and keeps what one client session sent and received."""

    def __init__(self, keep_frames: int = 1000) -> None:
        self.keep_frames = keep_frames
        self.token: str | None = None
        self.received = 0
        self.confirmed = 0  # the count our last session_ack told the bridge
        self.sent = 0
        self.unconfirmed: deque[str] = deque()
        self.first = 1  # the number of unconfirmed[0]
        self.resumes = 0
        self.lost = 0  # frames that could not be sent again (over keep_frames, or expired)

    def headers(self) -> dict[str, str]:
        """The handshake headers that ask for (or resume) a session."""
        if self.token is None:
            return {SESSION_HEADER: "new"}
        return {SESSION_HEADER: self.token, RECEIVED_HEADER: str(self.received)}

    def opened(self, headers: Mapping[str, str]) -> tuple[bool, list[str]]:
        """After a handshake: whether the session was resumed, and the frames to write
        again first (in order). A new session starts its counts from zero.

        Raises :class:`~roslibpy_lite.exceptions.RemoteProtocolError` when the bridge resumed
        the session with a received count that is malformed or more than we sent.
        """
        token = headers.get(SESSION_HEADER)
        got = headers.get(RECEIVED_HEADER)
        if token is not None and token == self.token and got is not None:
            count = parse_received(got, self.sent)
            self.acked(count)
            self.lost += max(0, self.first - count - 1)
            again = list(self.unconfirmed)
            self.unconfirmed.clear()
            self.first, self.sent = count + 1, count
            self.resumes += 1
            return True, again
        self.lost += len(self.unconfirmed) if self.token is not None else 0
        self.token = token  # None: this server keeps no sessions
        self.received = self.confirmed = self.sent = 0
        self.unconfirmed.clear()
        self.first = 1
        return False, []

    def wrote(self, frame: str) -> None:
        """One frame handed to the socket."""
        self.sent += 1
        unconfirmed = self.unconfirmed
        unconfirmed.append(frame)
        if len(unconfirmed) > self.keep_frames:
            unconfirmed.popleft()
            self.first += 1

    def acked(self, count: int) -> None:
        """The bridge received ``count`` frames of this session: forget those."""
        unconfirmed = self.unconfirmed
        while unconfirmed and self.first <= count:
            unconfirmed.popleft()
            self.first += 1
