"""What the bridge counts, in plain dicts and ints, with no prometheus_client: the sessions
count here (a client-only install runs them for ``MockRos``), and :mod:`.metrics` exports it
at scrape time (see its text for the names and the bounded labels).
"""

from __future__ import annotations

import bisect
import time
from typing import Any

__all__ = ["LABEL_LIMIT", "LATENCY_BUCKETS", "OTHER", "BridgeMetrics", "LabelCap", "outcome"]

LABEL_LIMIT = 200
"""Most distinct values of one name-valued label; the rest are ``"other"``."""
OTHER = "other"
LATENCY_BUCKETS = (0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0,
                   2.5, 5.0, 10.0)
"""Upper bounds (seconds) of the call duration histograms (``+Inf`` added)."""

class LabelCap:
    """Admits at most ``limit`` distinct label values; later ones become ``"other"``."""

    def __init__(self, limit: int = LABEL_LIMIT) -> None:
        self.limit = limit
        self.admitted: set[str] = set()

    def __call__(self, value: str) -> str:
        """``value`` if it is admitted (or there is room for it), else ``"other"``."""
        admitted = self.admitted
        if value in admitted:
            return value
        if len(admitted) < self.limit:
            admitted.add(value)
            return value
        return OTHER


def _bump(counts: dict[str, int], cap: LabelCap, key: str, n: int = 1) -> None:
    key = cap(key)
    counts[key] = counts.get(key, 0) + n


class _Timings:
    """Outcome counts and a duration histogram per name (services, or actions)."""

    def __init__(self) -> None:
        self.cap = LabelCap()
        self.data: dict[str, dict[str, Any]] = {}

    def observe(self, name: str, outcome: str, seconds: float) -> None:
        entry = self.data.get(name)
        if entry is None:
            name = self.cap(name)
            entry = self.data.get(name)
            if entry is None:
                entry = self.data[name] = {
                    "outcomes": {},
                    "buckets": [0] * (len(LATENCY_BUCKETS) + 1),
                    "sum": 0.0,
                }
        outcomes = entry["outcomes"]
        outcomes[outcome] = outcomes.get(outcome, 0) + 1
        entry["buckets"][bisect.bisect_left(LATENCY_BUCKETS, seconds)] += 1
        entry["sum"] += seconds


class BridgeMetrics:
    """One process's event counters (plain dicts), plus what closed objects counted.

    Every method is called on the loop thread.
    """

    def __init__(self) -> None:
        self.started = time.time()
        self.connections = 0
        self.refused: dict[str, int] = {}
        self.errors: dict[str, int] = {}
        self.services = _Timings()
        self.actions = _Timings()
        self._refused_cap = LabelCap(32)
        self._error_cap = LabelCap(32)
        self.topic_cap = LabelCap()
        # per topic: counts of closed subscriptions / publishes (never shrink)
        self.retired: dict[str, dict[str, int]] = {}

    # -- events --------------------------------------------------------------------------------

    def connection_refused(self, reason: str) -> None:
        """A connection was turned away (called by the security checks: auth, origin, limits)."""
        _bump(self.refused, self._refused_cap, reason)

    def error(self, kind: str) -> None:
        """An error of ``kind`` (``protocol``, ``request``, ``internal``, ...) happened."""
        _bump(self.errors, self._error_cap, kind)

    def service_call(self, service: str, outcome: str, seconds: float) -> None:
        """A client's ``call_service`` finished with ``outcome`` after ``seconds``."""
        self.services.observe(service, outcome, seconds)

    def action_goal(self, action: str, outcome: str, seconds: float) -> None:
        """Hook for actions: a goal sent through the bridge ended with ``outcome``
        (``succeeded``, ``aborted``, ``canceled``, ``failed``) after ``seconds``."""
        self.actions.observe(action, outcome, seconds)

    def _topic(self, topic: str) -> dict[str, int]:
        entry = self.retired.get(topic)
        if entry is None:
            entry = self.retired.setdefault(self.topic_cap(topic), {})
        return entry

    def topic_count(self, topic: str, field: str, n: int = 1) -> None:
        """Add ``n`` to a per-topic counter (``published``, ``published_bytes``, ``sent``, ...)."""
        entry = self._topic(topic)
        entry[field] = entry.get(field, 0) + n

    def published(self, topic: str, nbytes: int) -> None:
        """A client published one message of ``nbytes`` (its frame) to ``topic``."""
        entry = self._topic(topic)
        entry["published"] = entry.get("published", 0) + 1
        entry["published_bytes"] = entry.get("published_bytes", 0) + nbytes

    def retire_subscription(self, topic: str, sent: int, sent_bytes: int, drops: int) -> None:
        """A client's subscription closed: keep what it counted."""
        for field, n in (("sent", sent), ("sent_bytes", sent_bytes), ("drops", drops)):
            if n:
                self.topic_count(topic, field, n)

    def retire_ros_subscription(self, topic: str, received: int) -> None:
        """The bridge's ROS subscription to ``topic`` went away: keep its count."""
        if received:
            self.topic_count(topic, "ros_received", received)


# -- exposition ---------------------------------------------------------------------------------


def outcome(result: bool, values: object) -> str:
    """The ``outcome`` label of a finished service call from its ``service_response``."""
    if result:
        return "ok"
    text = values if isinstance(values, str) else ""
    if "timed out" in text:
        return "timeout"
    if "does not exist" in text or "not become available" in text or "no longer served" in text:
        return "unavailable"
    return "failed"
