"""Small messages never wait behind big ones on a robot's link: a Zenoh priority per topic.

A robot has one link to its router, and everything it sends crosses it: a 640x480 camera's
frame (900 KB) takes half a second of a 2 MB/s uplink, and a counter's 12 bytes put behind
it would wait that long. Zenoh keeps one queue per priority on each link and always sends
from the highest one that holds something (a big message goes in 64 KiB fragments, so a
small one of a higher priority overtakes it between two of them; what the kernel's send
buffer holds is sent in order, so the robot keeps it small: :mod:`.robot_link`). The
exporter gives every message a priority (:meth:`Priorities.of`) from its topic's **size
class** and its **QoS**:

==================  ================  =====================================================
largest message     priority          why
==================  ================  =====================================================
up to 4 KiB         ``data_high``     state, IMU, odometry, a counter: ahead of all bigger
up to 64 KiB        ``data``          scans, small clouds: Zenoh's default
over 64 KiB         ``data_low``      camera frames, point clouds (put whole from a thread
                                      of their own, latest wins: :mod:`.bulk`)
==================  ================  =====================================================

A best-effort topic (sensor data QoS) between 4 and 64 KiB goes one class lower than a
reliable one of its size (the newest scan is what a viewer wants). A topic's class is that
of the **largest message seen** and only ever goes down (messages of one topic never
overtake each other: Zenoh keeps order within one priority). None is *express* by default:
an express message is a batch of its own, and behind a camera the two batches Zenoh queues
per priority filled with them (a 100 Hz 12-byte topic lost 80 % of its messages through a
2 MB/s link, against 18 % batched). The robot's ``--relay-priority TOPIC=LEVEL`` fixes a
topic's priority (``LEVEL`` one of :data:`LEVELS`, ``+express`` to send it unbatched);
``*=data`` puts every topic at Zenoh's default, as before priorities.

Queries, replies, the graph and tokens keep Zenoh's default priority (``data``).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from functools import cached_property
from typing import Any

__all__ = ["EXPRESS_SUFFIX", "LEVELS", "SMALL_MESSAGE", "Priorities", "TopicPriority",
           "parse_overrides"]

LEVELS = ("real_time", "interactive_high", "interactive_low", "data_high", "data",
          "data_low", "background")
"""Zenoh's priorities, highest first, by the names ``--relay-priority`` takes."""

SMALL_MESSAGE = 4 * 1024
"""The largest message of a topic that goes first (``data_high``, express)."""

MEDIUM_MESSAGE = 64 * 1024
"""The largest message of a topic at Zenoh's default priority (``data``)."""

EXPRESS_SUFFIX = "+express"
"""Appended to a ``--relay-priority`` level: the topic's messages are sent unbatched."""

_DEFAULT = "data"


@dataclass(frozen=True)
class TopicPriority:
    """How a topic's messages go on the link: a level of :data:`LEVELS`, express, and
    whether they are big (put by :class:`~.bulk.BulkSender`)."""

    level: str = _DEFAULT
    express: bool = False
    bulk: bool = False

    @cached_property
    def kwargs(self) -> dict[str, Any]:
        """``priority`` and ``express`` for Zenoh's ``put`` and ``declare_publisher``."""
        import zenoh

        return {"priority": getattr(zenoh.Priority, self.level.upper()),
                "express": self.express}

    def __str__(self) -> str:
        return self.level + (EXPRESS_SUFFIX if self.express else "")


def parse_overrides(values: Iterable[str]) -> dict[str, TopicPriority]:
    """``--relay-priority`` values (``TOPIC=LEVEL[+express]``, ``*`` for every topic) by
    topic; ``ValueError`` naming the one that does not fit and what fits."""
    out: dict[str, TopicPriority] = {}
    for value in values:
        topic, sep, level = value.partition("=")
        express = level.endswith(EXPRESS_SUFFIX)
        level = level.removesuffix(EXPRESS_SUFFIX)
        if not sep or not topic or level not in LEVELS or (
                topic != "*" and not topic.startswith("/")):
            raise ValueError(
                f"--relay-priority {value!r}: expected TOPIC=LEVEL (TOPIC a topic name "
                f"starting with / or * for every topic; LEVEL one of {', '.join(LEVELS)}, "
                f"optionally followed by {EXPRESS_SUFFIX})")
        out[topic] = TopicPriority(level, express)
    return out


class Priorities:
    """The priority of each topic's messages on a robot's link (see the module's text)."""

    def __init__(self, overrides: dict[str, TopicPriority] | None = None) -> None:
        self.overrides = dict(overrides or {})
        self._chosen: dict[str, tuple[int, TopicPriority]] = {}
        """By topic: the rank of its class (only grows) and its priority."""
        self._classes = (TopicPriority("data_high"), TopicPriority("data"),
                         TopicPriority("data_low"), TopicPriority("data_low", bulk=True))

    def of(self, topic: str, size: int, reliable: bool = True) -> TopicPriority:
        """The priority of a message of ``size`` bytes of ``topic`` (``reliable``: its QoS),
        which is its topic's: the override, or the class of its largest message so far."""
        rank = 0 if size <= SMALL_MESSAGE else 1 if size <= MEDIUM_MESSAGE else 3
        if rank == 1 and not reliable:
            rank = 2
        chosen = self._chosen.get(topic)
        if chosen is not None and chosen[0] >= rank:
            return chosen[1]
        priority = self._classes[rank]
        fixed = self.overrides.get(topic) or self.overrides.get("*")
        if fixed is not None:
            priority = TopicPriority(fixed.level, fixed.express, priority.bulk)
        self._chosen[topic] = (rank, priority)
        return priority

    def forget(self, topic: str) -> None:
        """``topic`` is no longer watched: its class is chosen anew when it is."""
        self._chosen.pop(topic, None)

    def chosen(self) -> dict[str, str]:
        """Each watched topic's priority, as ``--relay-priority`` writes it (for the status)."""
        return {topic: str(p) for topic, (_rank, p) in sorted(self._chosen.items())}
