"""Reconnect delays: exponential growth, a cap, bounded jitter, reset."""

from __future__ import annotations

import random
from typing import Any

import pytest

from roslibpy_lite import Backoff


def test_delays_double_up_to_the_maximum() -> None:
    """Without jitter the delays are initial, 2x, 4x, ... pinned at the maximum."""
    b = Backoff(0.1, 1.0, jitter=0.0)
    assert [round(b.next(), 6) for _ in range(7)] == [0.1, 0.2, 0.4, 0.8, 1.0, 1.0, 1.0]


def test_jitter_stays_within_its_share() -> None:
    """With jitter j every delay lies in [(1-j)*base, base]."""
    b = Backoff(0.1, 5.0, jitter=0.5, rng=random.Random(7))
    for _ in range(200):
        base = b.base()
        delay = b.next()
        assert base * 0.5 <= delay <= base


def test_jitter_spreads_delays() -> None:
    """Two clients with different random sources do not sleep the same delays."""
    a = Backoff(rng=random.Random(1))
    b = Backoff(rng=random.Random(2))
    assert [a.next() for _ in range(5)] != [b.next() for _ in range(5)]


def test_reset_starts_over() -> None:
    """After reset the next delay is the initial one again."""
    b = Backoff(0.1, 5.0, jitter=0.0)
    for _ in range(10):
        b.next()
    b.reset()
    assert b.next() == pytest.approx(0.1)


def test_many_attempts_do_not_overflow() -> None:
    """Thousands of failed attempts keep returning the maximum."""
    b = Backoff(0.1, 5.0, jitter=0.0)
    for _ in range(5000):
        delay = b.next()
    assert delay == 5.0


@pytest.mark.parametrize(
    "kwargs",
    [{"initial": 0}, {"initial": 1.0, "maximum": 0.5}, {"factor": 0.5}, {"jitter": 1.5}],
)
def test_bad_settings_are_refused(kwargs: dict[str, Any]) -> None:
    """Nonsensical settings raise ValueError naming the setting."""
    with pytest.raises(ValueError, match="backoff"):
        Backoff(**kwargs)
