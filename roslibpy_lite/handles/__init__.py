"""The handles a backend returns: publishers, subscriptions, service servers.

The capabilities of :mod:`roslibpy_lite.capabilities` make them and supply the
hooks of :class:`Backend` (:class:`TopicBackend`, :class:`ServiceBackend`). Every handle

- is awaitable (``pub = await ros.advertise(...)``: returns once the
  request has been handed to the connection and, when the bridge confirms
  requests, accepted; a refusal raises there) and an async context manager
  (``async with ros.subscribe(...) as sub:``; closes on exit);
- closes with ``await handle.close()`` (or its specific name:
  ``unadvertise``, ``unsubscribe``); closing twice is harmless, using a closed
  handle raises :class:`~roslibpy_lite.exceptions.UsageError`.

Subscriptions deliver to callbacks or to their own bounded buffer:

- sync callbacks run in the receive path, in order, with no task per message;
- async callbacks run one at a time, in order, in one task per subscription,
  fed from the buffer;
- with no callback, messages wait in the buffer for ``async for`` /
  :meth:`Subscription.get`.

The buffer keeps at most ``buffer_size`` messages: when full, the OLDEST is
dropped and :attr:`Subscription.dropped` counts it. Who keeps and drops what between the
robot and this buffer (the bridge's ``queue_length``, the link, this buffer) is drawn in
one place: the "Buffers" section of the Publish and subscribe guide
(``docs/guides/pubsub.md``).

Fresh values do not go through the buffer: :meth:`Subscription.latest` is the newest
message received and its age, :meth:`Subscription.next` the first one after the call,
:meth:`Subscription.collect` every one during some seconds.

The package's modules, one job each: ``base`` (the hooks a handle needs from the capability
that made it, and what every handle shares), ``publisher``, ``subscription`` (a package: the
handle, its callbacks and its readers), ``services`` (a served service, a service call's
awaitable) and ``awaitables`` (the awaitables that say "did you forget await?").
"""

from __future__ import annotations

from typing import Protocol

from .base import Backend
from .publisher import Publisher, PublisherBackend
from .services import ServiceBackend, ServiceCall, ServiceServer
from .subscription import PAUSE_AFTER as PAUSE_AFTER
from .subscription import REPORT_WINDOW as REPORT_WINDOW
from .subscription import Collected, Latest, Subscription, SubscriptionBackend

__all__ = [
    "Backend",
    "Collected",
    "Latest",
    "Publisher",
    "ServiceBackend",
    "ServiceCall",
    "ServiceServer",
    "Subscription",
    "TopicBackend",
]


class TopicBackend(PublisherBackend, SubscriptionBackend, Protocol):
    """What publishers and subscriptions need
    (:class:`~roslibpy_lite.capabilities.topics.Topics`)."""
