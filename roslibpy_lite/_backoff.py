"""Exponential backoff with jitter, for reconnects.

Each failed attempt doubles the base delay (``initial``, ``2*initial``, ...)
up to ``maximum``; the delay actually slept is the base delay minus a random
share of up to ``jitter`` of it, so many clients restarted together do not
reconnect in lockstep. :meth:`Backoff.reset` starts over after a success.
"""

from __future__ import annotations

import random

__all__ = ["Backoff"]


class Backoff:
    """Delays for successive reconnect attempts.

    Args:
        initial: the first delay in seconds (> 0).
        maximum: the largest delay in seconds (>= initial).
        factor: growth per attempt (>= 1).
        jitter: share of each delay that is randomised, 0 (none) to 1 (full jitter).
        rng: the random source (a seeded ``random.Random`` makes delays repeatable).
    """

    def __init__(
        self,
        initial: float = 0.1,
        maximum: float = 5.0,
        *,
        factor: float = 2.0,
        jitter: float = 0.5,
        rng: random.Random | None = None,
    ) -> None:
        if not initial > 0:
            raise ValueError(f"backoff: initial must be > 0, got {initial!r}")
        if not maximum >= initial:
            raise ValueError(f"backoff: maximum ({maximum!r}) must be >= initial ({initial!r})")
        if not factor >= 1:
            raise ValueError(f"backoff: factor must be >= 1, got {factor!r}")
        if not 0 <= jitter <= 1:
            raise ValueError(f"backoff: jitter must be between 0 and 1, got {jitter!r}")
        self.initial = initial
        self.maximum = maximum
        self.factor = factor
        self.jitter = jitter
        self._rng = rng or random.Random()
        self.attempts = 0

    def base(self) -> float:
        """The delay before jitter for the next attempt."""
        return min(self.maximum, self.initial * self.factor**self.attempts)

    def next(self) -> float:
        """The delay to sleep before the next attempt; counts the attempt."""
        delay = self.base()
        if self.attempts < 64:  # past this the base is pinned at maximum anyway
            self.attempts += 1
        return delay * (1.0 - self.jitter * self._rng.random())

    def reset(self) -> None:
        """Start over from ``initial`` (after a successful connection)."""
        self.attempts = 0
