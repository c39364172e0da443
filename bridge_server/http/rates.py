"""Rates a person can read: averaged over a stated window, with the last minutes kept.

A rate measured over one tick of about a second flips with the tick's jitter (a steady
10 Hz topic read 10.0, then 5.0 when one message fell into the next tick). :class:`Window`
keeps the counters' samples of the last :data:`RATE_WINDOW` seconds and gives the rate over
that whole span; :class:`RateMeter` applies it to the bridge's per-topic counters and keeps
:data:`HISTORY_POINTS` per-second points of all topics' messages (``status.json``'s
``history``), so the status page plots the last 5 minutes as soon as it is loaded.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Iterable, Mapping
from typing import Any

__all__ = ["HISTORY_POINTS", "RATE_FIELDS", "RATE_WINDOW", "RateMeter", "Window",
           "merge_history"]

RATE_WINDOW = 5.0
"""Seconds a rate is averaged over (``status.json``'s ``rate_window_s``)."""
HISTORY_POINTS = 300
"""Points of ``history`` kept (one per tick of about a second: the last 5 minutes)."""
RATE_FIELDS = ("ros_received", "sent", "published", "sent_bytes", "published_bytes")
"""Per-topic counters a rate is given of (as ``<field>_per_s``)."""
_PLOTTED = (("to_clients", "sent"), ("from_clients", "published"),
            ("from_ros", "ros_received"))
"""``history``'s series: the key, and the counter it sums over the topics."""


class Window:
    """Counters by key, sampled now and then; rates over the last ``window`` seconds."""

    def __init__(self, window: float = RATE_WINDOW) -> None:
        self.window = window
        self._samples: deque[tuple[float, dict[str, tuple[float, ...]]]] = deque()

    def add(self, now: float, totals: Mapping[str, tuple[float, ...]]) -> None:
        """Take the counters' values at ``now`` (monotonic seconds)."""
        samples = self._samples
        samples.append((now, dict(totals)))
        while len(samples) > 2 and now - samples[1][0] >= self.window:
            samples.popleft()

    def rates(self) -> dict[str, tuple[float, ...]]:
        """Per key, each counter's increase per second from the oldest sample that has the
        key to the newest (keys without two samples yet have none)."""
        if len(self._samples) < 2:
            return {}
        t1, last = self._samples[-1]
        out: dict[str, tuple[float, ...]] = {}
        for key, values in last.items():
            t0, before = next(((t, s[key]) for t, s in self._samples if key in s))
            if t0 < t1:
                out[key] = tuple(max(v - b, 0.0) / (t1 - t0)
                                 for v, b in zip(values, before, strict=True))
        return out


class RateMeter:
    """Messages per second per topic over :data:`RATE_WINDOW`, and the per-second history
    of all topics' messages (called about once a second)."""

    def __init__(self) -> None:
        self.rates: dict[str, dict[str, float]] = {}
        self.window = Window()
        self._history: deque[tuple[float, float, tuple[float, ...]]] = deque(
            maxlen=HISTORY_POINTS)
        self._sums: tuple[float, ...] | None = None
        self._t = time.monotonic()

    def tick(self, totals: Mapping[str, Mapping[str, Any]]) -> None:
        """Take new totals: the rates over the window, and one more history point."""
        now = time.monotonic()
        values = {name: tuple(float(t.get(f, 0)) for f in RATE_FIELDS)
                  for name, t in totals.items()}
        self.window.add(now, values)
        self.rates = {
            name: {f"{f}_per_s": round(r, 1) for f, r in zip(RATE_FIELDS, rates, strict=True)}
            for name, rates in self.window.rates().items() if any(values[name])}
        sums = tuple(sum(float(t.get(f, 0)) for t in totals.values()) for _, f in _PLOTTED)
        if self._sums is not None:
            dt = max(now - self._t, 1e-3)
            self._history.append((time.time(), dt, tuple(
                max(s - b, 0.0) for s, b in zip(sums, self._sums, strict=True))))
        self._sums, self._t = sums, now

    def history(self) -> dict[str, Any]:
        """``status.json``'s ``history``: per point its wall time ``t`` and, per series,
        messages per second over that point's interval (oldest first)."""
        points = list(self._history)
        out: dict[str, Any] = {"window_s": HISTORY_POINTS, "t": [round(t, 1) for t, _, _ in
                                                                   points]}
        for i, (key, _) in enumerate(_PLOTTED):
            out[f"{key}_per_s"] = [round(counts[i] / dt, 2) for _, dt, counts in points]
        return out


def merge_history(histories: Iterable[Mapping[str, Any] | None]) -> dict[str, Any] | None:
    """Several workers' ``history`` as one: points matched from the newest, rates added up
    (messages from ROS: the largest, as each worker receives the same ROS stream)."""
    found = [h for h in histories if h]
    if not found:
        return None
    n = min(len(h["t"]) for h in found)
    out: dict[str, Any] = {"window_s": found[0]["window_s"], "t": found[0]["t"][-n:] if n
                           else []}
    for key, _ in _PLOTTED:
        series = [h[f"{key}_per_s"][len(h["t"]) - n:] for h in found]
        pick = max if key == "from_ros" else sum
        out[f"{key}_per_s"] = [round(pick(column), 2) for column in zip(*series, strict=True)]
    return out
