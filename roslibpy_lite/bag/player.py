"""Playing an MCAP file through the bridge with its recorded timing (see the package docstring)."""

from __future__ import annotations

import asyncio
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .reader import info, read

if TYPE_CHECKING:
    from ..api import Ros
    from ..handles import Publisher

__all__ = ["PlayStats", "play"]

_LATCHED = re.compile(r"durability:\s*(1|transient_local)\b")


@dataclass
class PlayStats:
    """What :func:`play` published: ``late_max_ms``/``late_mean_ms`` is how far behind the
    recorded timing (scaled by the rate) messages went out."""

    messages: int = 0
    topics: int = 0
    loops: int = 0
    late_max_ms: float = 0.0
    late_mean_ms: float = 0.0


async def play(
    ros: Ros,
    path: str | Path,
    *,
    rate: float = 1.0,
    loop: bool = False,
    topics: Iterable[str] | None = None,
    start: float = 0.0,
    duration: float | None = None,
    latch: Iterable[str] = (),
) -> PlayStats:
    """Publish the messages of ``path`` through ``ros`` with the recorded timing.

    ``rate`` scales time (2.0: twice as fast); ``loop`` starts over at the end until
    cancelled; ``topics`` plays only those; ``start``/``duration`` (seconds from the
    first message) cut a window. Topics recorded as latched (rosbag2's QoS says
    transient local), and those in ``latch``, are advertised latched, so a subscriber
    that comes later still gets their last message. Types come from the file's own
    schemas, so the robot's own interfaces play without msgs knowing them.
    """
    if rate <= 0:
        from ..exceptions import UsageError

        raise UsageError(f"play: rate must be > 0, got {rate}")
    about = info(path)
    latched = set(latch) | {t.topic for t in about.topics if _LATCHED.search(t.qos)}
    begin = about.start_ns + int(start * 1e9)
    end = begin + int(duration * 1e9) if duration is not None else None
    publishers: dict[str, Publisher[Any]] = {}
    stats = PlayStats()
    late_total = 0.0
    clock = asyncio.get_running_loop()
    try:
        while True:
            wall0: float | None = None
            for msg in read(path, topics, start_ns=begin, end_ns=end):
                typed = msg.decode()
                pub = publishers.get(msg.topic)
                if pub is None:
                    pub = publishers[msg.topic] = await ros.advertise(
                        msg.topic, type(typed), latch=msg.topic in latched)
                if wall0 is None:
                    wall0 = clock.time()
                target = wall0 + (msg.log_time_ns - begin) / 1e9 / rate
                delay = target - clock.time()
                if delay > 0:
                    await asyncio.sleep(delay)  # the recorded timing itself, not a wait
                late = max(0.0, clock.time() - target) * 1000
                stats.late_max_ms = max(stats.late_max_ms, late)
                late_total += late
                await pub.publish(typed)
                stats.messages += 1
            stats.loops += 1
            if not loop or wall0 is None:
                break
    finally:
        stats.topics = len(publishers)
        stats.late_mean_ms = late_total / stats.messages if stats.messages else 0.0
        for pub in publishers.values():
            await pub.close()
    return stats
