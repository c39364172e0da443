"""Session tokens name the worker that keeps the session (--workers), and only then."""

from __future__ import annotations

import pytest

from rosbridge_core.session.resume import ResumeConfig, SessionStore, worker_of


def test_a_workers_token_names_it_and_keeps_its_random_part() -> None:
    """A worker's tokens start with ``w<index>.`` and carry the same 128 random bits."""
    tokens = {SessionStore(ResumeConfig(), worker=3).new_token() for _ in range(100)}
    assert len(tokens) == 100
    for token in tokens:
        assert token.startswith("w3.") and len(token) == len("w3.") + 22
        assert worker_of(token) == 3


def test_without_workers_a_token_names_no_worker() -> None:
    """Without --workers tokens are as before: the random part alone, naming no worker."""
    token = SessionStore(ResumeConfig()).new_token()
    assert len(token) == 22 and worker_of(token) is None  # "." is not in its alphabet


@pytest.mark.parametrize("token", ["", "new", "w.abc", "wx.abc", "w1abc", "W1.abc", "w\u0663.abc",
                                   "w12345.abc", " w1.abc"])
def test_a_token_without_a_worker_prefix_names_no_worker(token: str) -> None:
    """Anything but ``w``, 1 to 4 ASCII digits and a dot names no worker (served where it
    lands, as an unknown token)."""
    assert worker_of(token) is None
