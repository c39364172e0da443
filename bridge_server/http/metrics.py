"""Prometheus metrics of the bridge, counted cheaply and exported at scrape time.

The hot paths never call prometheus_client. Per-message work only raises plain
``int`` attributes that already sit on the objects involved (a subscription's
``sent``/``sent_bytes``/``dropped_total``, a shared ROS subscription's
``received``). Rarer events (connections, refusals, errors, service calls,
publishes from clients) go to a :class:`BridgeMetrics` of plain dicts. At scrape
time :func:`bridge_server.http.snapshot.take` turns the live state plus the
recorder into a JSON-able snapshot, snapshots of all workers are merged, and
:func:`render` builds the metric families with prometheus_client's own
``*MetricFamily`` classes and exposition code.

Metric names and labels (all prefixed ``roslibpy_bridge_``)
------------------------------------------------------------
================================================  =========  ==========================
name                                              type       labels
================================================  =========  ==========================
``info``                                          gauge      version
``workers``                                       gauge
``start_time_seconds``                            gauge      (earliest worker start)
``clients``                                       gauge      (connected now)
``clients_by_protocol``                           gauge      protocol (rosbridge, foxglove)
``sessions_kept``                                 gauge      (dropped clients' sessions)
``sessions_resumed_total``                        counter
``sessions_expired_total``                        counter
``sessions_forwarded_total``                      counter    (resumes passed to another worker)
``connections_total``                             counter    (accepted websocket clients)
``connections_refused_total``                     counter    reason
``topic_subscribers``                             gauge      topic
``ros_messages_received_total``                   counter    topic (from ROS, once each)
``messages_total``                                counter    topic, direction
``bytes_total``                                   counter    topic, direction
``queue_drops_total``                             counter    topic (all clients)
``client_queue_drops_total``                      counter    client, topic (connected)
``client_queued_messages``                        gauge      client (waiting to be sent)
``resume_kept_frames``                            gauge      client (sent, not yet confirmed)
``service_calls_total``                           counter    service, outcome
``service_call_duration_seconds``                 histogram  service
``action_goals_total``                            counter    action, outcome
``action_goal_duration_seconds``                  histogram  action
``errors_total``                                  counter    kind
================================================  =========  ==========================

``direction`` is ``ros_to_client`` (frames written to clients, counted per
client) or ``client_to_ros`` (messages clients published). ``outcome`` of a
service call is ``ok``, ``failed``, ``timeout`` or ``unavailable``. ``kind``
of an error is ``protocol`` (a frame that does not decode), ``request`` (a
request the bridge refused, answered with a status error) or ``internal``.
``client`` is ``<worker>-<session id>``.

A relay (:mod:`bridge_server.zenoh.relay_web`) exports every robot's families at once with
:func:`render_labelled`: each series carries one more label, ``robot``.

Bounded labels
--------------
Every name-valued label (topic, service, action, reason, kind) admits at most
:data:`LABEL_LIMIT` distinct values, first come first served for the life of
the process; later values are folded into ``"other"``, so a client flooding
new topic names cannot grow the series without limit. ``client`` labels show
at most :data:`CLIENT_LIMIT` connected clients (lowest ids); the rest fold
into ``"other"``. With ``--workers`` each worker keeps its own admission list
for the scrapes it answers, so past the limit two scrapes may fold differently.

The counting itself (:class:`BridgeMetrics`, :class:`LabelCap`, :func:`outcome`) is in
:mod:`.counters`, which needs no prometheus_client. Actions: the action ops call
:meth:`BridgeMetrics.action_goal` (exported even while no action exists).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping
from typing import Any

from prometheus_client.core import (
    CounterMetricFamily,
    GaugeMetricFamily,
    HistogramMetricFamily,
    Metric,
)
from prometheus_client.exposition import CONTENT_TYPE_LATEST, generate_latest

from bridge_server.http.status import COUNTERS
from rosbridge_core.counters import (
    LABEL_LIMIT,
    LATENCY_BUCKETS,
    OTHER,
    BridgeMetrics,
    LabelCap,
    outcome,
)

__all__ = [
    "CLIENT_LIMIT",
    "CONTENT_TYPE",
    "LABEL_LIMIT",
    "LATENCY_BUCKETS",
    "OTHER",
    "BridgeMetrics",
    "LabelCap",
    "outcome",
    "render",
    "render_labelled",
]

PREFIX = "roslibpy_bridge_"
CLIENT_LIMIT = 100
"""Most clients shown one by one in the per-client metrics."""
CONTENT_TYPE = CONTENT_TYPE_LATEST


class _Families:
    """A collector over one merged snapshot (what ``generate_latest`` asks for)."""

    def __init__(self, snap: Mapping[str, Any], caps: Mapping[str, LabelCap]) -> None:
        self.snap = snap
        self.caps = caps

    def collect(self) -> Iterator[Metric]:
        s = self.snap
        topic = self.caps["topic"]

        def g(name: str, doc: str, labels: list[str] | None = None) -> GaugeMetricFamily:
            return GaugeMetricFamily(PREFIX + name, doc, labels=labels)

        def c(name: str, doc: str, labels: list[str] | None = None) -> CounterMetricFamily:
            return CounterMetricFamily(PREFIX + name, doc, labels=labels)

        info = g("info", "The bridge's version.", ["version"])
        info.add_metric([str(s.get("version", ""))], 1)
        yield info
        yield GaugeMetricFamily(PREFIX + "workers", "Worker processes answering this port.",
                                value=len(s.get("workers", [])) or 1)
        yield GaugeMetricFamily(PREFIX + "start_time_seconds",
                                "Unix time the earliest running worker started.",
                                value=float(s.get("started", 0.0)))
        clients = s.get("clients", [])
        yield GaugeMetricFamily(PREFIX + "clients", "Connected websocket clients.",
                                value=len([c for c in clients if not c.get("parked")]))
        by_protocol = GaugeMetricFamily(PREFIX + "clients_by_protocol",
                                        "Connected websocket clients by the protocol they speak.",
                                        labels=["protocol"])
        for name in ("rosbridge", "foxglove"):
            by_protocol.add_metric([name], len([c for c in clients if not c.get("parked")
                                                and c.get("protocol", "rosbridge") == name]))
        yield by_protocol
        yield GaugeMetricFamily(PREFIX + "sessions_kept",
                                "Sessions of dropped clients kept for them to resume.",
                                value=len([c for c in clients if c.get("parked")]))
        for count in COUNTERS:  # the bridge status's count fields (status.py)
            yield CounterMetricFamily(PREFIX + count.name, count.help,
                                      value=int(s.get(count.name, 0)))
        refused = c("connections_refused", "Connections turned away, by reason.", ["reason"])
        for reason, n in _folded(s.get("refused", {}), self.caps["reason"]):
            refused.add_metric([reason], n)
        yield refused
        errors = c("errors", "Errors, by kind (protocol, request, internal).", ["kind"])
        for kind, n in _folded(s.get("errors", {}), self.caps["kind"]):
            errors.add_metric([kind], n)
        yield errors

        topics: dict[str, dict[str, float]] = {}
        for name, t in s.get("topics", {}).items():
            acc = topics.setdefault(topic(name), {})
            for field, v in t.items():
                if isinstance(v, int | float) and not isinstance(v, bool):
                    acc[field] = acc.get(field, 0) + v
        subs = g("topic_subscribers", "Client subscriptions per topic.", ["topic"])
        ros_in = c("ros_messages_received", "Messages the bridge took from ROS per topic.",
                   ["topic"])
        msgs = c("messages", "Messages per topic and direction.", ["topic", "direction"])
        nbytes = c("bytes", "Bytes of frames per topic and direction.", ["topic", "direction"])
        drops = c("queue_drops", "Messages dropped from full client queues, per topic.",
                  ["topic"])
        for name in sorted(topics):
            t = topics[name]
            subs.add_metric([name], t.get("subscribers", 0))
            ros_in.add_metric([name], t.get("ros_received", 0))
            msgs.add_metric([name, "ros_to_client"], t.get("sent", 0))
            msgs.add_metric([name, "client_to_ros"], t.get("published", 0))
            nbytes.add_metric([name, "ros_to_client"], t.get("sent_bytes", 0))
            nbytes.add_metric([name, "client_to_ros"], t.get("published_bytes", 0))
            drops.add_metric([name], t.get("drops", 0))
        yield from (subs, ros_in, msgs, nbytes, drops)

        cdrops = c("client_queue_drops", "Messages dropped per connected client and topic.",
                   ["client", "topic"])
        queued = g("client_queued_messages", "Messages waiting to be sent, per client.",
                   ["client"])
        kept = g("resume_kept_frames", "Frames written to a client in a resumable session and "
                 "not yet confirmed by it (kept to send again after a dropped link).",
                 ["client"])
        per_drop: dict[tuple[str, str], int] = {}
        per_queued: dict[str, int] = {}
        per_kept: dict[str, int] = {}
        shown = sorted(clients, key=lambda cl: (cl.get("worker", 0), cl.get("sid", 0)))
        for i, cl in enumerate(shown):
            cid = str(cl["id"]) if i < CLIENT_LIMIT else OTHER
            per_queued[cid] = per_queued.get(cid, 0) + int(cl.get("queued", 0))
            per_kept[cid] = per_kept.get(cid, 0) + int(cl.get("resume_kept", 0))
            for sub in cl.get("subscriptions", []):
                key = (cid, topic(sub["topic"]))
                per_drop[key] = per_drop.get(key, 0) + int(sub.get("dropped", 0))
        for (cid, tname), n in sorted(per_drop.items()):
            cdrops.add_metric([cid, tname], n)
        for cid, n in sorted(per_queued.items()):
            queued.add_metric([cid], n)
        for cid, n in sorted(per_kept.items()):
            kept.add_metric([cid], n)
        yield cdrops
        yield queued
        yield kept

        for kind, label in (("service_calls", "service"), ("action_goals", "action")):
            what = kind[:-1]
            total = c(f"{what}s", f"{label.capitalize()} calls by outcome.",
                      [label, "outcome"])
            hist = HistogramMetricFamily(
                PREFIX + f"{what}_duration_seconds", f"{label.capitalize()} call durations.",
                labels=[label],
            )
            merged: dict[str, dict[str, Any]] = {}
            for name, entry in s.get(kind, {}).items():
                add_timing(merged, self.caps[label](name), entry)
            for name in sorted(merged):
                entry = merged[name]
                for result, n in sorted(entry["outcomes"].items()):
                    total.add_metric([name, result], n)
                cumulative = 0
                buckets: list[tuple[str, float]] = []
                for bound, n in zip((*LATENCY_BUCKETS, float("inf")), entry["buckets"],
                                    strict=True):
                    cumulative += n
                    buckets.append(("+Inf" if bound == float("inf") else repr(bound),
                                    cumulative))
                hist.add_metric([name], buckets, entry["sum"])
            yield total
            yield hist


def add_timing(into: dict[str, dict[str, Any]], name: str, entry: Mapping[str, Any]) -> None:
    """Add one name's outcome counts and histogram (``entry``) to ``into[name]``."""
    acc = into.get(name)
    if acc is None:
        acc = into[name] = {"outcomes": {}, "buckets": [0] * len(entry["buckets"]), "sum": 0.0}
    outcomes = acc["outcomes"]
    for result, n in entry["outcomes"].items():
        outcomes[result] = outcomes.get(result, 0) + n
    acc["buckets"] = [a + b for a, b in zip(acc["buckets"], entry["buckets"], strict=True)]
    acc["sum"] += entry["sum"]


def _folded(counts: Mapping[str, int], cap: LabelCap) -> list[tuple[str, int]]:
    out: dict[str, int] = {}
    for key, n in counts.items():
        k = cap(key)
        out[k] = out.get(k, 0) + n
    return sorted(out.items())


def new_caps() -> dict[str, LabelCap]:
    """The exporting process's label caps (kept for its lifetime, so series stay stable)."""
    return {name: LabelCap() for name in ("topic", "service", "action", "reason", "kind")}


def render(snap: Mapping[str, Any], caps: Mapping[str, LabelCap],
           extra: Iterable[Metric] = ()) -> bytes:
    """The Prometheus text exposition of a (merged) snapshot, and the ``extra`` families
    (a robot's replay windows)."""
    return generate_latest(_Then(_Families(snap, caps), extra))


class _Then:
    """A collector of ``first``'s families, then the ``extra`` ones."""

    def __init__(self, first: _Families, extra: Iterable[Metric]) -> None:
        self.first = first
        self.extra = list(extra)

    def collect(self) -> Iterator[Metric]:
        yield from self.first.collect()
        yield from self.extra


class _Labelled:
    """A collector over several bridges' snapshots: one family per metric name, each
    bridge's series with one more label naming it (a relay's robots)."""

    def __init__(self, snaps: Iterable[tuple[str, Mapping[str, Any], Mapping[str, LabelCap]]],
                 label: str, extra: Iterable[Metric]) -> None:
        self.snaps = list(snaps)
        self.label = label
        self.extra = list(extra)

    def collect(self) -> Iterator[Metric]:
        merged: dict[str, Metric] = {}
        for value, snap, caps in self.snaps:
            for family in _Families(snap, caps).collect():
                acc = merged.get(family.name)
                if acc is None:
                    acc = merged[family.name] = Metric(family.name, family.documentation,
                                                       family.type, family.unit)
                acc.samples += [sample._replace(labels={self.label: value, **sample.labels})
                                for sample in family.samples]
        yield from self.extra
        yield from merged.values()


def render_labelled(snaps: Iterable[tuple[str, Mapping[str, Any], Mapping[str, LabelCap]]],
                    label: str, extra: Iterable[Metric] = ()) -> bytes:
    """The exposition of several bridges' ``(name, snapshot, caps)``: every series of each
    carries ``label="<name>"`` (a relay's ``robot``), after the ``extra`` families."""
    return generate_latest(_Labelled(snaps, label, extra))
