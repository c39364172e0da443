"""A subscription to one topic (:class:`Subscription`), in parts: ``fields`` (what the
parts share), ``callbacks`` (registering, running, and those that raise), ``reading`` (the
buffer and fresh messages) and ``handle`` (the handle itself: request, receive path,
closing)."""

from __future__ import annotations

from .callbacks import PAUSE_AFTER, REPORT_WINDOW
from .handle import Subscription, SubscriptionBackend
from .reading import Collected, Latest

__all__ = ["PAUSE_AFTER", "REPORT_WINDOW", "Collected", "Latest", "Subscription",
           "SubscriptionBackend"]
