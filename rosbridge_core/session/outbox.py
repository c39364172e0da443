"""What one client has yet to be sent: its queues, the drop policy and the writer.

Outgoing queues and the drop policy
-----------------------------------
Every subscription (one per topic, whatever the number of ids) has its own
bounded queue of ``queue_length`` messages (0 means :data:`DEFAULT_QUEUE_LENGTH`);
when it is full the OLDEST message of that subscription is dropped. Replies
(service responses, status ops, ROS calls to client-served services) go to a
separate control queue, bounded by ``control_limit`` (oldest dropped, logged).
The per-ROS-message fan-out only appends to these queues and sets an event;
one writer task per client drains them into the socket, so a client that
stops reading holds at most its queues plus the socket's write buffer, and
never delays anyone else. Dropped messages are counted per subscription and
reported to the client as a ``status`` warning (``dropped N messages on
/topic ...``) at most once per ``drop_report_interval`` seconds (5 s); drops
inside that interval are summed into the next report. ``set_level`` ``error``
silences these warnings.

The writer gathers whatever is ready (up to :data:`BATCH_FRAMES` frames or
:data:`BATCH_BYTES` bytes) and writes it with one socket write. When it is
idle, the first message or reply queued in a turn of the loop is written at
once, without waiting for the writer's turn (:meth:`Outbox._kick`); the writer
is woken only if more follows in the same turn.

A message costs a viewer one write
----------------------------------
A message is encoded once per encoding, and framed once per encoding and topic
spelling: its websocket frame, header included, is kept on the message
(``framed``) and the same bytes go to every client that gets it that way
(:func:`shared_frame`). When nothing of a client's is waiting and its socket takes
data, :meth:`Outbox.push` writes those bytes at once, without queueing them:
a viewer of a topic costs the server a socket write and a few checks. A
subscription with a ``fragment_size`` or another protocol's framing
(Foxglove) frames its messages per client; a resumable session keeps its
frames unframed (to send them again) and takes the queue; with an extension
(``--compression deflate``) websockets frames them.

Merged subscriptions
--------------------
Several subscribe ops of one client to one topic (different ids) share one
:class:`TopicQueue`, and each message is sent once. The merged options are:
the least ``throttle_rate``, the largest ``queue_length``, the least
``fragment_size``, and the ``compression`` of the latest subscribe.
``throttle_rate`` keeps the newest message of a burst and sends it when the
interval is over. ``fragment_size`` applies to JSON text only (binary CBOR
frames are never split).
"""

from __future__ import annotations

import asyncio
import itertools
import logging
import time
import weakref
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING

from rosbridge_core.interfaces import ReportedError
from rosbridge_core.protocol import ops
from rosbridge_core.protocol.constants import INTERNAL_ERROR
from rosbridge_core.protocol.frames import split_fragments
from rosbridge_core.session.frames import (
    JOINED_BYTES,
    Frame,
    Wire,
    frame_bytes,
    frame_parts,
    header,
    joined,
)

if TYPE_CHECKING:
    from rosbridge_core.graph import Message as Incoming
    from rosbridge_core.graph import TopicFeed as _Shared
    from rosbridge_core.session.link import ClientLink
    from rosbridge_core.session.resume import SentFrames

__all__ = [
    "BATCH_BYTES",
    "BATCH_FRAMES",
    "DEFAULT_QUEUE_LENGTH",
    "JOINED_BYTES",
    "Frame",
    "Outbox",
    "TopicQueue",
    "Wire",
    "frame_bytes",
    "frame_parts",
    "shared_frame",
]

log = logging.getLogger("bridge_server.session")

DEFAULT_QUEUE_LENGTH = 100
"""Bound of a subscription's queue when the client asked for ``queue_length`` 0."""

BATCH_FRAMES = 128
"""Most frames the writer sends with one socket write."""

BATCH_BYTES = 256 * 1024
"""Most bytes the writer gathers for one socket write (a large frame goes alone)."""



class TopicQueue:
    """One client's (merged) subscription to one topic: its options and its queue."""

    def __init__(self, outbox: Outbox, topic: str, spelled: str) -> None:
        self.outbox = outbox
        self.topic = topic
        self.spelled = None if spelled == topic else spelled  # the client's spelling, if different
        self.ids: dict[ops.Id | None, ops.Subscribe] = {}
        self.shared: _Shared | None = None
        self.queue: deque[Incoming] = deque()
        self.maxlen = DEFAULT_QUEUE_LENGTH
        self.throttle = 0.0
        self.fragment_size: int | None = None
        self.compression = "none"
        self.last_sent = 0.0
        self.pending: Incoming | None = None
        self.timer: asyncio.TimerHandle | None = None
        self.dropped = 0
        self.dropped_total = 0
        self.sent = 0  # frames of this subscription written, and their bytes (for /metrics)
        self.sent_bytes = 0
        self.last_report = -1e9
        self.report_timer: asyncio.TimerHandle | None = None
        self.active = True
        self.encode: Callable[[Incoming], Frame] | None = None  # a frame of its own
        self.key: tuple[str, str | None] = (self.compression, self.spelled)  # see shared_frame()

    def configure(self, default_len: int, max_len: int = 0, min_fragment: int = 0) -> None:
        """Merge the options of every id: least throttle, largest queue, least fragment size
        (the queue at most ``max_len``, fragments at least ``min_fragment`` bytes)."""
        subs = list(self.ids.values())
        self.throttle = min(s.throttle_rate for s in subs) / 1000.0
        lens = [s.queue_length or default_len for s in subs]
        self.maxlen = min(max(lens), max_len) if max_len else max(lens)
        sizes = [s.fragment_size for s in subs if s.fragment_size]
        self.fragment_size = max(min(sizes), min_fragment) if sizes else None
        self.compression = subs[-1].compression
        self.key = (self.compression, self.spelled)
        while len(self.queue) > self.maxlen:
            self.queue.popleft()
            self.outbox.queued -= 1

    def on_message(self, inc: Incoming) -> None:
        """Called on the loop for each message of the topic: throttle, then queue."""
        if self.throttle > 0:
            now = time.monotonic()
            wait = self.last_sent + self.throttle - now
            if wait > 0:
                self.pending = inc
                if self.timer is None:
                    self.timer = self.outbox.loop.call_later(wait, self._flush)
                return
            self.last_sent = now
        self.outbox.push(self, inc)

    def _flush(self) -> None:
        self.timer = None
        inc, self.pending = self.pending, None
        if inc is not None and self.active:
            self.last_sent = time.monotonic()
            self.outbox.push(self, inc)

    def close(self) -> None:
        """Stop delivering: clear the queue and any throttle timer."""
        self.active = False
        self.outbox.queued -= len(self.queue)
        self.queue.clear()
        if self.report_timer is not None:
            self.report_timer.cancel()
            self.report_timer = None
        self.pending = None
        if self.timer is not None:
            self.timer.cancel()
            self.timer = None


def _size(frame: Frame) -> int:
    if isinstance(frame, Wire):
        return frame.size
    return len(frame) if not isinstance(frame, tuple) else len(frame[0]) + len(frame[1])


def shared_frame(sub: TopicQueue, inc: Incoming) -> Wire | None:
    """The message's frame for ``sub`` as it goes on the socket, made once per encoding and
    topic spelling and kept on the message for every other client (``None`` when ``sub``
    frames per client: fragments, another protocol's framing)."""
    if sub.encode is not None or sub.fragment_size is not None:
        return None
    key = sub.key
    cache = inc.framed
    if cache is None:
        cache = inc.framed = {}
    else:
        made: Wire | None = cache.get(key)
        if made is not None:
            return made
    encoded = inc.encoded(sub.compression, sub.spelled)
    pieces: tuple[bytes, ...]
    if isinstance(encoded, str):
        if len(encoded) > JOINED_BYTES:  # not kept twice (text and bytes): encoded per client
            return None
        pieces = (encoded.encode(),)
        first = 0x81  # FIN, text
    else:  # a payload the encoding made in two parts (cbor-raw) is not joined here either
        pieces = encoded if isinstance(encoded, tuple) else (encoded,)
        first = 0x82  # FIN, binary
    size = sum(map(len, pieces))
    head = header(first, size)
    if size <= JOINED_BYTES:
        parts = (b"".join((head, *pieces)),)
    elif len(pieces[0]) <= JOINED_BYTES:  # the encoding's own small head joins the frame's
        parts = (head + pieces[0], *pieces[1:])
    else:
        parts = (head, *pieces)
    made = cache[key] = Wire(parts)
    return made


class _Turn:
    """Tells a turn of the event loop from the next (one per loop): ``n`` changes after a
    turn in which some outbox wrote at once, so the next message in that turn waits for its
    writer, which gathers it with what follows into one write; one callback per turn for
    every client, not one per client."""

    __slots__ = ("armed", "loop", "n")

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self.loop = loop
        self.n = 0
        self.armed = False

    def mark(self) -> int:
        """A direct write happened in this turn: the turn's number."""
        if not self.armed:
            self.armed = True
            self.loop.call_soon(self._next)
        return self.n

    def _next(self) -> None:
        self.armed = False
        self.n += 1


_TURNS: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, _Turn] = (
    weakref.WeakKeyDictionary())


def _turn_of(loop: asyncio.AbstractEventLoop) -> _Turn:
    turn = _TURNS.get(loop)
    if turn is None:
        turn = _TURNS[loop] = _Turn(loop)
    return turn


class Outbox:
    """One client's outgoing queues and the task that writes them to its socket.

    ``warn`` is how a drop report reaches the client (a ``status`` warning, subject to
    the client's ``set_level``).
    """

    def __init__(
        self,
        link: ClientLink,
        sid: int,
        control_limit: int,
        max_queued: int,
        drop_report_interval: float,
        warn: Callable[[str], None],
    ) -> None:
        self.link = link
        self.sid = sid
        self.loop = asyncio.get_running_loop()
        self.control_limit = control_limit
        self.max_queued = max_queued or 1 << 62
        self.drop_report_interval = drop_report_interval
        self.warn = warn
        self.control: deque[str | bytes] = deque()
        self.order: deque[TopicQueue] = deque()
        self.queued = 0  # messages in all of this client's subscription queues
        self.control_dropped = 0
        self.closed = False
        self.wake = asyncio.Event()
        self.idle = False  # the writer waits for something to write (see _kick)
        self.frag_ids = itertools.count()
        self.sent: SentFrames | None = None  # kept until confirmed, in a resumable session
        self.ack: str | None = None  # a session_ack to write first (not counted, not kept)
        self.turn = _turn_of(self.loop)
        self.wrote_in = -1  # the turn of this outbox's last direct write
        self.direct = False  # whether the outbox may write between the writer's rounds
        self.framing = False  # and frame what it writes itself (see _connection)
        self._connection(link)

    def _connection(self, link: ClientLink) -> None:
        """Write to ``link`` from now on: whether the outbox may write to it between the
        writer's rounds (:meth:`_kick`), and frame messages itself (no extension, no frame
        logging), which :meth:`push` needs to write a message at once."""
        self.link = link
        self.direct = link.direct
        self.framing = self.direct and link.framing

    # -- filling -------------------------------------------------------------------------------

    def send_text(self, text: str | bytes) -> None:
        """Queue one control frame (replies and status) for the writer."""
        if self.closed:
            return
        control = self.control
        if len(control) >= self.control_limit:
            control.popleft()
            self.control_dropped += 1
            if self.control_dropped in (1, 10, 100) or self.control_dropped % 1000 == 0:
                log.warning(
                    "session %d: dropped %d replies: the client does not read",
                    self.sid,
                    self.control_dropped,
                )
        control.append(text)
        self._kick()

    def push(self, sub: TopicQueue, inc: Incoming) -> None:
        """Write one message of ``sub`` at once when nothing of this client's waits and its
        socket takes data (the first in this turn of the loop); else queue it, dropping the
        subscription's oldest when full (or when the client's queues hold ``max_queued``
        messages in all)."""
        if (
            self.idle
            and not self.queued
            and not self.control
            and self.framing
            and self.wrote_in != self.turn.n
            and self.sent is None
            and not self.closed
            and self.link.writable()
        ):
            # written at once (or dropped as one that does not encode)
            cache = inc.framed
            framed = cache.get(sub.key) if cache is not None and sub.encode is None else None
            if framed is None or sub.fragment_size is not None:
                try:
                    framed = shared_frame(sub, inc)
                    if framed is None:
                        parts = tuple(frame_parts(self._frames(sub, inc)))
                        size = sum(map(len, parts))
                    else:
                        parts, size = framed.parts, framed.size
                except ReportedError:  # counted and logged where it came from (a relay's robot)
                    return
                except Exception:
                    log.exception("session %d: cannot encode a message of %s", self.sid,
                                  sub.topic)
                    return
            else:
                parts, size = framed.parts, framed.size
            if len(parts) == 1:
                self.link.transport.write(parts[0])
            else:
                self.link.transport.writelines(parts)
            turn = self.turn
            if not turn.armed:
                turn.mark()
            self.wrote_in = turn.n
            sub.sent += 1
            sub.sent_bytes += size
            return
        q = sub.queue
        if len(q) >= sub.maxlen or (self.queued >= self.max_queued and q):
            q.popleft()
            sub.dropped += 1
            sub.dropped_total += 1
            self._note_drop(sub)
        elif self.queued >= self.max_queued:  # full with other subscriptions' messages
            sub.dropped += 1
            sub.dropped_total += 1
            self._note_drop(sub)
            return
        else:
            self.order.append(sub)
            self.queued += 1
        q.append(inc)
        self._kick()

    def send_ack(self, text: str) -> None:
        """Write this ``session_ack`` ahead of everything (it replaces one not yet written)."""
        self.ack = text
        self.wake.set()

    def acked(self, count: int) -> None:
        """The client confirmed ``count`` frames of a resumable session: forget those."""
        if self.sent is not None:
            self.sent.acked(count)

    def resume(self, link: ClientLink, count: int) -> int:
        """Write to ``link`` from now on, starting with the frames after the client's
        ``count``; returns how many of those were no longer kept."""
        self._connection(link)
        if self.sent is None:
            return 0
        again, missing = self.sent.since(count)
        self.control.extendleft(reversed(again))
        self.wake.set()
        return missing

    def close(self) -> None:
        """Nothing more is queued; the writer stops."""
        self.closed = True
        self.wake.set()

    def _note_drop(self, sub: TopicQueue) -> None:
        if sub.report_timer is not None:
            return  # a report is already scheduled
        wait = sub.last_report + self.drop_report_interval - time.monotonic()
        if wait > 0:
            sub.report_timer = self.loop.call_later(wait, self._report_drops, sub)
        else:
            self._report_drops(sub)

    def _report_drops(self, sub: TopicQueue) -> None:
        sub.report_timer = None
        n, sub.dropped = sub.dropped, 0
        if n == 0 or not sub.active:
            return
        sub.last_report = time.monotonic()
        log.info("session %d: dropped %d messages on %s", self.sid, n, sub.topic)
        self.warn(
            f"dropped {n} messages on {sub.topic} (queue_length {sub.maxlen}, "
            f"{sub.dropped_total} in all): the client reads slower than messages arrive"
        )

    # -- writing -------------------------------------------------------------------------------

    def _kick(self) -> None:
        """Something was queued: if the writer is parked with nothing in flight, write what
        is queued right now (the writer is woken only if more follows in this turn, see
        :meth:`_settle`); else wake the writer.

        Waking the writer costs a turn of the loop before anything is written: that was
        a lone message's or reply's largest share of its time in the bridge. What else is
        queued in the same turn waits for the writer, which gathers it into one write.
        """
        if self.idle and not self.closed and self.direct and self.wrote_in != self.turn.n:
            link = self.link
            if link.writable():
                try:
                    link.write(self._take())
                except Exception:
                    log.exception("session %d: a write failed; closing the connection", self.sid)
                    self.closed = True
                    self.idle = False
                    self.loop.create_task(link.close(INTERNAL_ERROR, "internal error"))
                else:
                    # what is queued after it in this turn wakes the writer; with nothing
                    # more, the writer stays parked and the next message (in a later turn)
                    # is written at once again, without a task's wake-up
                    self.wrote_in = self.turn.mark()
                    return
        self.wake.set()

    def write_queued(self) -> None:
        """Write what is queued now, in this call, where the link takes it at once (the
        in-memory link: MockRos delivers what a client's op sets off before its call returns);
        the writer task finds the queues emptied."""
        if not self.closed and self.link.writable():
            frames = self._take()
            if frames:
                self.link.write(frames)

    async def writer(self) -> None:
        """Write what is queued until the outbox is closed (run as the client's task)."""
        link = self.link
        wake = self.wake
        try:
            while not self.closed:
                frames = self._take()
                if not frames:
                    wake.clear()
                    self.idle = True  # _kick may write for the writer until it runs again
                    try:
                        await wake.wait()
                    finally:
                        self.idle = False
                    continue
                async with link.send_context():
                    link.write(frames)
        except link.closed_errors:
            pass
        except Exception:
            log.exception("session %d: the writer failed; closing the connection", self.sid)
            await link.close(INTERNAL_ERROR, "internal error")

    def _take(self) -> list[Frame]:
        """The frames to write next (:meth:`_collect`), kept in a resumable session until the
        client confirms them, after a ``session_ack`` to send first."""
        sent = self.sent
        # framed only matters to topic messages: a batch of replies alone does not ask the link
        framed = sent is None and self.framing and self.link.raw_ok() if self.order else False
        frames = self._collect(framed)
        if sent is not None:  # kept until the client confirms them
            for frame in frames:
                sent.add(joined(frame))
            if self.ack is not None:
                frames.insert(0, self.ack)
                self.ack = None
        return frames

    def _collect(self, framed: bool = False) -> list[Frame]:
        """Take the frames ready to go: replies first, then messages in arrival order
        (``framed``: each message's frame as it goes on the socket, where it can be shared)."""
        frames: list[Frame] = []
        size = 0
        control = self.control
        order = self.order
        while control and len(frames) < BATCH_FRAMES and size < BATCH_BYTES:
            frame = control.popleft()
            frames.append(frame)
            size += len(frame)
        while order and len(frames) < BATCH_FRAMES and size < BATCH_BYTES:
            sub = order.popleft()
            if not sub.queue:
                continue
            inc = sub.queue.popleft()
            self.queued -= 1
            try:
                shared = shared_frame(sub, inc) if framed else None
                encoded = [shared] if shared is not None else self._frames(sub, inc)
            except ReportedError:  # counted and logged where it came from (a relay's robot)
                continue
            except Exception:
                log.exception("session %d: cannot encode a message of %s", self.sid, sub.topic)
                continue
            before = size
            for piece in encoded:
                frames.append(piece)
                size += _size(piece)
            sub.sent += 1
            sub.sent_bytes += size - before
        return frames

    def _frames(self, sub: TopicQueue, inc: Incoming) -> list[Frame]:
        if sub.encode is not None:  # another protocol's framing (bridge_server.foxglove)
            return [sub.encode(inc)]
        encoded = inc.encoded(sub.compression, sub.spelled)
        size = sub.fragment_size
        if size is not None and isinstance(encoded, str) and len(encoded) > size:
            return list(split_fragments(encoded, size, f"{sub.topic}:{next(self.frag_ids)}"))
        return [encoded]

    def send_split(
        self, text: str, size: int | None, frag_id: ops.Id | None, prefix: str
    ) -> None:
        """Queue ``text`` as one control frame, or as fragments of ``size`` characters when
        it is longer (with the id ``frag_id``, or ``prefix:n`` without one)."""
        if size is not None and len(text) > size:
            fid = frag_id if frag_id is not None else f"{prefix}:{next(self.frag_ids)}"
            for piece in split_fragments(text, size, fid):
                self.send_text(piece)
        else:
            self.send_text(text)

    def stats(self) -> tuple[int, int]:
        """Replies waiting and replies dropped (the subscriptions count their own)."""
        return len(self.control), self.control_dropped
