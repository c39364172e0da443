"""The player's options on MockRos (in memory, so each publish is seen the moment it is made):
the recorded timing scaled by ``rate`` (a message never goes out before its time), ``loop``,
``start``/``duration``, ``topics`` and ``latch``."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any, cast

import pytest
from mcap_ros2.writer import Writer as Ros2Writer

from msgs.dynamic import full_text
from roslibpy_lite import MockRos
from roslibpy_lite.bag import play

T0 = 1_700_000_000_000_000_000
A_TIMES = [0.0, 0.1, 0.2, 0.3, 0.4, 0.5]  # seconds from the first message, on /a
B_TIMES = [0.05, 0.25, 0.45]  # on /b


@pytest.fixture
def bag(tmp_path: Path) -> Path:
    """A file with /a (6 messages 0.1 s apart) and /b (3 between them), std_msgs/String
    whose data says topic and time."""
    path = tmp_path / "two.mcap"
    entries = sorted([(t, "/a") for t in A_TIMES] + [(t, "/b") for t in B_TIMES])
    with path.open("wb") as f:
        writer = Ros2Writer(f)
        schema = writer.register_msgdef("std_msgs/msg/String", full_text("std_msgs/msg/String"))
        for t, topic in entries:
            stamp = T0 + round(t * 1e9)
            writer.write_message(topic, schema, {"data": f"{topic} {t:g}"},
                                 log_time=stamp, publish_time=stamp)
        writer.finish()  # type: ignore[no-untyped-call]
    return path


async def _play_and_watch(path: Path, **options: Any) -> tuple[list[tuple[float, str]], Any]:
    """Play ``path`` on a MockRos whose subscriptions note when each message came (seconds
    after play was called) and what it said; the stats too."""
    seen: list[tuple[float, str]] = []
    clock = asyncio.get_running_loop()
    called = clock.time()
    async with MockRos() as ros:
        for topic in ("/a", "/b"):
            sub = await ros.subscribe(topic, "std_msgs/msg/String")
            sub.on_message(lambda m: seen.append((clock.time() - called, m["data"])))
        called = clock.time()
        stats = await play(ros, path, **options)
    return seen, stats


@pytest.mark.parametrize("rate", [1.0, 2.5])
async def test_messages_go_out_at_their_recorded_time_scaled_by_rate(bag: Path,
                                                                     rate: float) -> None:
    """Each message goes out no earlier than its recorded offset / rate after play starts,
    in recorded order; the whole play takes at least the recording's length / rate."""
    seen, stats = await _play_and_watch(bag, rate=rate)
    expected = sorted([(t, f"/a {t:g}") for t in A_TIMES] + [(t, f"/b {t:g}") for t in B_TIMES])
    assert [data for _, data in seen] == [data for _, data in expected]
    for (when, data), (t, _) in zip(seen, expected, strict=True):
        assert when >= t / rate - 1e-3, (data, when, t / rate)
    assert stats.messages == 9 and stats.topics == 2 and stats.loops == 1


async def test_start_duration_and_topics_cut_what_is_played(bag: Path) -> None:
    """``start``/``duration`` keep the window from start to start + duration (timed from the
    window's start); ``topics`` keeps only the named topics."""
    seen, stats = await _play_and_watch(bag, start=0.15, duration=0.2, topics=["/a"])
    assert [data for _, data in seen] == ["/a 0.2", "/a 0.3"]
    assert seen[1][0] >= 0.3 - 0.15 - 1e-3  # offsets count from the window's start
    assert stats.messages == 2 and stats.topics == 1


async def test_loop_starts_over_until_cancelled(bag: Path) -> None:
    """``loop``: the file plays again from its start, each round with its recorded timing,
    until the task is cancelled."""
    seen: list[tuple[float, str]] = []
    clock = asyncio.get_running_loop()
    third = asyncio.Event()

    def on_a(m: Any) -> None:
        seen.append((clock.time(), m["data"]))
        if len(seen) == 2 * len(A_TIMES) + 1:
            third.set()

    async with MockRos() as ros:
        sub = await ros.subscribe("/a", "std_msgs/msg/String")
        sub.on_message(on_a)
        called = clock.time()
        task = asyncio.create_task(play(ros, bag, loop=True, topics=["/a"], rate=4.0))
        await asyncio.wait_for(third.wait(), 20)
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task
    names = [f"/a {t:g}" for t in A_TIMES]
    assert [data for _, data in seen[:13]] == names + names + names[:1]
    second_round = seen[len(A_TIMES)][0]
    assert second_round - called >= 0.5 / 4.0 - 1e-3  # after the first round's last message
    for (when, _), t in zip(seen[len(A_TIMES):2 * len(A_TIMES)], A_TIMES, strict=True):
        assert when - second_round >= t / 4.0 - 1e-3


class _Kept:
    """A publisher the player closes that stays advertised (its ``close`` is kept for later):
    ROS drops a latched message with its last publisher, so a subscriber that comes after the
    play comes while the player's publishers are still there."""

    def __init__(self, pub: Any) -> None:
        self.pub = pub

    async def publish(self, msg: Any) -> None:
        await self.pub.publish(msg)

    async def close(self) -> None:
        """Kept open until the test closes ``pub``."""


class _KeepingPublishers:
    """The MockRos ``ros`` whose publishers the player cannot close (:class:`_Kept`)."""

    def __init__(self, ros: MockRos) -> None:
        self.ros = ros
        self.kept: list[Any] = []

    async def advertise(self, *args: Any, **kwargs: Any) -> _Kept:
        pub = await self.ros.advertise(*args, **kwargs)
        self.kept.append(pub)
        return _Kept(pub)


async def test_latch_keeps_the_last_message_for_a_late_subscriber(bag: Path) -> None:
    """Topics in ``latch`` are advertised latched: a subscriber that comes after the play
    still gets the topic's last message; an unlatched topic gives it nothing."""
    async with MockRos() as ros:
        held = _KeepingPublishers(ros)
        stats = await play(cast(Any, held), bag, latch=["/b"], rate=10.0)
        late_b = await ros.subscribe("/b", "std_msgs/msg/String")
        late_a = await ros.subscribe("/a", "std_msgs/msg/String")
        assert (await late_b.get(timeout=5))["data"] == "/b 0.45"
        await ros.drain()  # delivery in MockRos is done once this returns
        assert late_a.received == 0
        for pub in held.kept:
            await pub.close()
    assert stats.messages == 9
