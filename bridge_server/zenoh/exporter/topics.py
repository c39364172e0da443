"""Topics, demand-driven: a topic is subscribed in ROS only while some relay's demand token
for it exists (an unwatched robot sends nothing); each message is put once, as the CDR
bytes that came, however many relays and viewers watch it; a reliable topic's through an
advanced publisher that keeps a bounded window of its last messages for relays whose link
dropped (:mod:`~bridge_server.zenoh.replay`: nothing lost in an outage within the window);
a big one's whole, the latest winning (:mod:`~bridge_server.zenoh.bulk`). The loop only
numbers a message and hands it on: it is put by the robot's putting thread
(:mod:`~bridge_server.zenoh.putter`), which may wait for the link where the loop must not."""

from __future__ import annotations

import secrets
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial

import zenoh

from bridge_server.zenoh import keys
from bridge_server.zenoh.bulk import BulkSender
from bridge_server.zenoh.exporter.base import log
from bridge_server.zenoh.exporter.policy import RelayPolicy
from bridge_server.zenoh.keys import PLACE, Meta
from bridge_server.zenoh.link import answering
from bridge_server.zenoh.priority import Priorities, TopicPriority
from bridge_server.zenoh.putter import Putter
from bridge_server.zenoh.replay import ReplayBudget, ReplayPublisher, ReplayWindow
from rosbridge_core.graph import Message, TopicFeed
from rosbridge_core.interfaces import BridgeError

__all__ = ["TopicExports"]


@dataclass
class _Export:
    """One watched topic: the Graph's feed, the relays that watch it, the last message put."""

    feed: TopicFeed
    listener: Callable[[Message], None]
    relays: set[str] = field(default_factory=set)
    seq: int = 0
    epoch: str = field(default_factory=lambda: secrets.token_hex(6))
    """This stream of the topic: a topic watched anew starts again at seq 1, in a new epoch."""
    last: tuple[Message, bytes] | None = None
    replay: ReplayPublisher | None = None
    """The topic's advanced publisher with its window (made at its first reliable message;
    made, used and closed on the putting thread only)."""
    windowed: bool = False
    """It has a replay window, or one is being made (the loop's view of :attr:`replay`)."""
    lingering: bool = False
    """No relay watches it, and it stays a while (:data:`~.replay.DEMAND_LINGER`)."""


class TopicExports(RelayPolicy):
    """The exporter's part that puts the topics relays watch."""

    exports: dict[str, _Export]
    priorities: Priorities
    """Each topic's Zenoh priority on the robot's link (``--relay-priority`` overrides)."""
    bulk: BulkSender | None
    """Puts the big messages (:mod:`.bulk`), once the session is open."""
    putter: Putter
    """Puts every message of a watched topic, off the loop (:mod:`.putter`)."""
    replay: ReplayWindow
    """How much of each reliable topic is kept for relays whose link dropped."""
    replay_budget: ReplayBudget
    demand_linger: float
    graph_changed: Callable[[], None]

    def _on_demand(self, sample: zenoh.Sample) -> None:
        try:
            relay, topic = keys.parse_demand(str(sample.key_expr))
        except IndexError:
            return
        export = self.exports.get(topic)
        if sample.kind == zenoh.SampleKind.PUT:
            if self.refusal("subscribe", topic, relay) is not None:
                return
            if export is None:
                export = self._export(topic)
                if export is None:
                    return
            export.relays.add(relay)
        elif export is not None:
            export.relays.discard(relay)
            if not export.relays:
                if not export.windowed:
                    self._unwatched(topic)
                elif not export.lingering:  # its relays may be cut off: keep its window
                    export.lingering = True
                    self._loop.call_later(self.demand_linger, self._linger, topic, export)

    def _linger(self, topic: str, export: _Export) -> None:
        """A replayed topic no relay watched for a while: unsubscribed once the link has
        been up ``demand_linger`` s with no relay asking for it again."""
        if self.exports.get(topic) is not export or export.relays:
            export.lingering = False
            return
        wait = self._uplink_since + self.demand_linger - self._loop.time()
        if not self.uplinks or wait > 0:  # its relays cannot say whether they still watch
            self._loop.call_later(max(wait, self.demand_linger if not self.uplinks else 0.0),
                                  self._linger, topic, export)
            return
        self._unwatched(topic)

    def _unwatched(self, topic: str) -> None:
        export = self.exports.pop(topic)
        self._unexport(export)
        self.priorities.forget(topic)
        log.info("nobody watches %s through a relay now: unsubscribed", topic)

    def _unexport(self, export: _Export) -> None:
        self.graph.unsubscribe(export.feed, export.listener)
        if export.windowed:  # after its last message, on the putting thread
            export.windowed = False
            self.putter.submit(partial(_close_window, export))

    def _export(self, topic: str) -> _Export | None:
        key = f"{self.robot}/{topic[1:]}"

        def listener(msg: Message) -> None:
            if self.session is None:
                return
            payload, attachment = self._stamp(export, msg)
            qos = self.priorities.of(topic, len(payload), getattr(export.feed, "reliable", True))
            replayed = not qos.bulk and self._replayed(export, msg)
            export.windowed = replayed or (export.windowed and not qos.bulk)
            if self.putter.submit(partial(self._put, export, key, topic, payload, attachment,
                                          qos, replayed), len(payload)):
                self.uplink.sent(len(payload))

        try:
            feed = self.graph.subscribe(topic, None, listener)
        except (BridgeError, ValueError) as exc:
            log.warning("a relay asked for %s, which cannot be subscribed: %s", topic, exc)
            return None
        export = self.exports[topic] = _Export(feed, listener)
        self.graph_changed()  # the type may be learned later: the bridge's refresh does it
        log.info("a relay watches %s: subscribed", topic)
        return export

    def _put(self, export: _Export, key: str, topic: str, payload: bytes, attachment: bytes,
             qos: TopicPriority, replayed: bool) -> None:
        """Put one message of ``export`` (on the putting thread: it may wait for the link),
        through its window if ``replayed``."""
        session = self.session
        if session is None:
            return
        if qos.bulk and self.bulk is not None:  # a big topic: whole, latest wins (.bulk)
            _close_window(export)  # and not replayed (.replay)
            self.bulk.put(key, payload, attachment, qos.kwargs)
        elif replayed:
            if export.replay is None:
                export.replay = ReplayPublisher(session, key, self.replay, topic,
                                                self.replay_budget)
            export.replay.put(payload, attachment, qos)
        else:
            session.put(key, payload, attachment=attachment, **qos.kwargs)

    def _replayed(self, export: _Export, msg: Message) -> bool:
        """Whether ``msg`` goes through the topic's window: a reliable, volatile topic's
        (a best-effort or latched one's latest wins), with a window."""
        feed = export.feed
        return (self.replay.count > 0 and feed.latched is not msg
                and bool(getattr(export.feed, "reliable", True))
                and not getattr(feed, "transient_local", False))

    def replay_windows(self) -> dict[str, tuple[int, int]]:
        """What each replayed topic's window holds now: (messages, payload bytes)."""
        # each window read once: the putting thread may close it meanwhile
        return {topic: (w.held, w.held_bytes) for topic, e in self.exports.items()
                if (w := e.replay) is not None}

    def _stamp(self, export: _Export, msg: Message) -> tuple[bytes, bytes]:
        """The payload and attachment of ``msg``, numbered in its topic's stream."""
        last = export.last
        if last is not None and last[0] is msg:
            return msg.data, last[1]
        export.seq += 1
        meta = Meta(type=export.feed.type_name or "", latched=export.feed.latched is msg,
                    stamp_ns=msg.stamp_ns, epoch=export.epoch, seq=export.seq, zid=self.zid)
        attachment = meta.encode()
        export.last = (msg, attachment)
        return msg.data, attachment

    def _answer_latched(self, query: zenoh.Query) -> None:
        """A relay that starts watching a topic asks for its latched message, and with
        :data:`PLACE` for where a replayed topic's stream is now: an empty reply whose
        attachment numbers the last message put (its viewers take nothing up to there from
        the window); a topic neither latched nor replayed has no answer."""
        with answering(query):
            topic = keys.name_of(str(query.key_expr), 2)
            export = self.exports.get(topic)
            if export is None:
                return
            latched = export.feed.latched
            if latched is not None:
                payload, attachment = self._stamp(export, latched)
                query.reply(query.key_expr, payload, attachment=attachment)
            elif export.windowed and PLACE in query.parameters:
                meta = Meta(type=export.feed.type_name or "", epoch=export.epoch,
                            seq=export.seq, zid=self.zid)
                query.reply(query.key_expr, b"", attachment=meta.encode())


def _close_window(export: _Export) -> None:
    """Close ``export``'s replay window, if it has one (on the putting thread)."""
    if export.replay is not None:
        export.replay.close()
        export.replay = None
