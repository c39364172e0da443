"""A session's settings, from the command line (``bridge_server.__main__``)."""

from __future__ import annotations

from dataclasses import dataclass

from rosbridge_core.session.outbox import DEFAULT_QUEUE_LENGTH

__all__ = ["SessionConfig"]


@dataclass
class SessionConfig:
    """Per-session limits and defaults (set from the command line)."""

    default_queue_length: int = DEFAULT_QUEUE_LENGTH
    control_limit: int = 10_000
    call_timeout: float = 5.0
    served_call_timeout: float = 10.0
    drop_report_interval: float = 5.0
    discovery_wait: float = 2.0
    max_calls_in_flight: int = 1024
    goal_timeout: float = 0.0  # action goals: seconds before one is canceled/aborted, 0 = never
