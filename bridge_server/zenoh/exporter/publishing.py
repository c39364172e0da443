"""Publishing for relays' clients: a relay's publisher token (under ``@advertise``) makes a
shared publisher of the Graph, and the messages put under ``@in/`` are published through
it, CDR bytes as they came."""

from __future__ import annotations

import zenoh

from bridge_server.zenoh import keys
from bridge_server.zenoh.exporter.base import log
from bridge_server.zenoh.exporter.policy import RelayPolicy
from bridge_server.zenoh.keys import Meta
from rosbridge_core.graph import Publisher
from rosbridge_core.interfaces import BridgeError

__all__ = ["UNHELD_PUBLISHER_WAIT", "Publishing"]

UNHELD_PUBLISHER_WAIT = 10.0
"""Seconds a publisher made for a message under ``@in/`` that no relay's ``@advertise``
token holds is kept: the token may come after the first message (Zenoh carries
declarations and data apart), or never (the message came after the token went, or from a
relay that holds none); then the publisher goes."""


class Publishing(RelayPolicy):
    """The exporter's part that publishes in ROS what relays' clients publish."""

    publishers: dict[tuple[str, str, bool], tuple[Publisher, set[str]]]
    """The publishers made for relays by (topic, type, latched), and the relays whose
    ``@advertise`` token holds each."""
    unheld_wait: float
    _unheld: set[tuple[str, str, bool]]

    def _on_advertise(self, sample: zenoh.Sample) -> None:
        try:
            relay, topic, latch, type_name = keys.parse_advertise(str(sample.key_expr))
        except IndexError:
            return
        entry = (topic, type_name, latch)
        if sample.kind == zenoh.SampleKind.PUT:
            if self.refusal("publish", topic, relay) is not None:
                return
            if self._publisher(entry) is not None:
                self.publishers[entry][1].add(relay)
            return
        held = self.publishers.get(entry)
        if held is not None:
            held[1].discard(relay)
            self._release_unheld(entry)

    def _publisher(self, entry: tuple[str, str, bool]) -> Publisher | None:
        held = self.publishers.get(entry)
        if held is not None:
            return held[0]
        topic, type_name, latch = entry
        try:
            cls = self.graph.resolve_message(type_name)
            pub = self.graph.acquire_publisher(topic, cls, latch, 10)
        except (BridgeError, ValueError) as exc:
            log.warning("a relay's publisher of %s (%s) cannot be made: %s", topic, type_name,
                        exc)
            return None
        self.publishers[entry] = (pub, set())
        return pub

    def _on_in(self, sample: zenoh.Sample) -> None:
        topic = keys.name_of(str(sample.key_expr), 2)
        try:
            meta = Meta.decode(sample.attachment.to_bytes() if sample.attachment else None)
        except BridgeError as exc:
            log.warning("a message for %s from a relay is dropped: %s", topic, exc)
            return
        if self.refusal("publish", topic) is not None:
            return
        entry = (topic, meta.type, meta.latched)
        pub = self._publisher(entry)
        if pub is None:
            return
        pub.publish(sample.payload.to_bytes())
        if not self.publishers[entry][1] and entry not in self._unheld:
            self._unheld.add(entry)
            self._loop.call_later(self.unheld_wait, self._drop_unheld, entry)

    def _drop_unheld(self, entry: tuple[str, str, bool]) -> None:
        self._unheld.discard(entry)
        if self._release_unheld(entry):
            log.info("no relay advertises %s (%s): its publisher made for a message went",
                     entry[0], entry[1])

    def _release_unheld(self, entry: tuple[str, str, bool]) -> bool:
        """Release ``entry``'s publisher if no relay's token holds it (True if it went)."""
        held = self.publishers.get(entry)
        if held is None or held[1]:
            return False
        del self.publishers[entry]
        self.graph.release_publisher(held[0])
        return True
