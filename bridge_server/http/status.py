"""The bridge's status, typed: what ``/status.json`` shows and ``/metrics`` exports.

:class:`BridgeStatus` is one worker's status; its fields, in their order, are the keys of
``/status.json`` (:meth:`BridgeStatus.to_json`). A count the bridge keeps (connections,
resumed sessions...) is one field whose metadata is :func:`counter`, which carries its help text.
Every field is a required keyword, so :func:`~bridge_server.http.snapshot.take` does not
type-check until it gives the new field's value (from where one worker counts it); from
the field alone

- :func:`~bridge_server.http.snapshot.merge` adds it up over the workers,
- :mod:`~bridge_server.http.metrics` exports it as the counter
  ``roslibpy_bridge_<field>_total`` with that help,

and ``tests/ops/test_status_fields.py`` checks that the metrics tables of the docs name it.
The clients' entries are the sessions' own
:class:`~rosbridge_core.session.client_status.ClientStatus`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from rosbridge_core.session.client_status import ClientStatus

__all__ = ["COUNTERS", "BridgeStatus", "Counter", "counter"]


@dataclass(frozen=True)
class Counter:
    """What a count field of :class:`BridgeStatus` says of itself."""

    name: str
    """The ``/status.json`` key; the metric is ``roslibpy_bridge_<name>_total``."""
    help: str
    """The metric's help text."""


_COUNTER = "counter"


def counter(help: str) -> dict[str, str]:
    """The metadata of a count field of :class:`BridgeStatus` (summed over workers; ``help``
    is its metric's help text): ``dataclasses.field(metadata=counter(help))``, a field
    without a default, so that :func:`~bridge_server.http.snapshot.take` must give it."""
    return {_COUNTER: help}


@dataclass(frozen=True, kw_only=True)
class BridgeStatus:
    """One worker's status (a merge of several workers' has the same keys)."""

    version: str
    worker: int
    workers: list[dict[str, Any]]
    """Per worker: ``index``, ``pid``, ``node``, ``started``, ``clients``."""
    started: float
    connections: int = field(metadata=counter("Websocket clients accepted."))
    sessions_resumed: int = field(metadata=counter("Sessions resumed by a client."))
    sessions_expired: int = field(metadata=counter("Kept sessions that ended unresumed."))
    sessions_forwarded: int = field(metadata=counter(
        "Session resumes a worker passed on to the worker keeping the session (--workers)."))
    refused: dict[str, int]
    """Connections turned away, by reason."""
    errors: dict[str, int]
    """Errors, by kind."""
    service_calls: dict[str, dict[str, Any]]
    """Per service: outcome counts and a duration histogram."""
    action_goals: dict[str, dict[str, Any]]
    """Per action: outcome counts and a duration histogram."""
    topics: dict[str, dict[str, Any]]
    """Per topic: counts, type, rates."""
    clients: tuple[ClientStatus, ...]
    services: list[dict[str, Any]]
    """Services clients serve."""
    actions: list[dict[str, Any]]
    """Actions clients serve or send goals to."""

    def to_json(self) -> dict[str, Any]:
        """The ``/status.json`` of this worker: the fields, in their order."""
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        out["clients"] = [client.to_json() for client in self.clients]
        return out


COUNTERS: tuple[Counter, ...] = tuple(
    Counter(f.name, f.metadata[_COUNTER]) for f in dataclasses.fields(BridgeStatus)
    if _COUNTER in f.metadata)
"""The count fields of :class:`BridgeStatus`, in their order."""

