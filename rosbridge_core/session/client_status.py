"""What one client's session is doing, typed: the entry of ``clients`` in ``/status.json``.

Each session kind (a rosbridge :class:`~rosbridge_core.session.session.Session`, a
:class:`~bridge_server.foxglove.session.FoxgloveSession`) describes itself with
:func:`client_status` from what it really holds; the snapshot
(:mod:`bridge_server.http.snapshot`) reads that, and nothing else, of a session.
The JSON is :meth:`ClientStatus.to_json`: the dataclasses' fields, in their order.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Sized
from dataclasses import dataclass
from typing import Any, Protocol

__all__ = ["ClientStatus", "SubscriptionStatus", "client_status"]


# What client_status reads of a session's subscriptions and outbox (outbox.py's
# TopicQueue and Outbox), as protocols: this module imports nothing of the sessions'.
class _Typed(Protocol):
    @property
    def type_name(self) -> str | None: ...


class _TopicQueue(Protocol):
    @property
    def topic(self) -> str: ...
    @property
    def shared(self) -> _Typed | None: ...
    @property
    def queue(self) -> Sized: ...
    @property
    def maxlen(self) -> int: ...
    @property
    def dropped_total(self) -> int: ...
    @property
    def sent(self) -> int: ...


class _Kept(Protocol):
    @property
    def frames(self) -> Sized: ...


class _Outbox(Protocol):
    @property
    def control(self) -> Sized: ...
    @property
    def control_dropped(self) -> int: ...
    @property
    def sent(self) -> _Kept | None: ...


@dataclass(frozen=True)
class SubscriptionStatus:
    """One subscription of a client."""

    topic: str
    type: str | None
    """Its ROS type, ``None`` until the bridge's ROS subscription knows it."""
    queued: int
    """Messages waiting to be sent to the client."""
    queue_length: int
    """Most messages it queues (older ones are dropped past it)."""
    dropped: int
    """Messages dropped from its full queue."""
    sent: int
    """Frames of it written to the client."""


@dataclass(frozen=True)
class ClientStatus:
    """One connected (or kept) client, as the status page and ``/metrics`` see it."""

    id: str
    """``<worker>-<session id>``: the ``client`` label of the per-client metrics."""
    sid: int
    worker: int
    protocol: str
    """``rosbridge`` or ``foxglove``."""
    address: str
    connected_at: float
    subscriptions: tuple[SubscriptionStatus, ...]
    publishes: tuple[str, ...]
    serves: tuple[str, ...]
    calls_in_flight: int
    parked: bool
    """Kept for its client to resume (resume.py), with no connection now."""
    queued: int
    """Messages and control frames waiting to be sent."""
    dropped: int
    """Messages and control frames dropped from full queues."""
    resume_kept: int
    """Frames written and not yet confirmed by the client (resume.py): about what is in
    flight on a live link, growing while its link is down."""

    def to_json(self) -> dict[str, Any]:
        """The client's entry in ``/status.json`` (keys are the field names)."""
        return dataclasses.asdict(self, dict_factory=_json_dict)


def _json_dict(items: Iterable[tuple[str, Any]]) -> dict[str, Any]:
    """``asdict``'s dicts with tuples as lists (what ``json.dumps`` writes either way)."""
    return {k: list(v) if isinstance(v, tuple) else v for k, v in items}


def client_status(*, sid: int, worker: int, protocol: str, address: str, connected_at: float,
                  subs: Iterable[_TopicQueue], outbox: _Outbox, publishes: Iterable[str],
                  serves: Iterable[str], calls_in_flight: int, parked: bool) -> ClientStatus:
    """A session's status from its subscriptions, its outbox and what it publishes and
    serves (what every session kind holds)."""
    subs = list(subs)
    return ClientStatus(
        id=f"{worker}-{sid}", sid=sid, worker=worker, protocol=protocol, address=address,
        connected_at=connected_at,
        subscriptions=tuple(
            SubscriptionStatus(
                topic=sub.topic,
                type=sub.shared.type_name if sub.shared is not None else None,
                queued=len(sub.queue), queue_length=sub.maxlen, dropped=sub.dropped_total,
                sent=sub.sent)
            for sub in subs),
        publishes=tuple(sorted(publishes)),
        serves=tuple(sorted(serves)),
        calls_in_flight=calls_in_flight,
        parked=parked,
        queued=sum(len(sub.queue) for sub in subs) + len(outbox.control),
        dropped=sum(sub.dropped_total for sub in subs) + outbox.control_dropped,
        resume_kept=len(outbox.sent.frames) if outbox.sent is not None else 0,
    )
