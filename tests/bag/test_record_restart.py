"""A recording across a restart of the bridge itself (killed: its sessions are gone, so the
client's subscriptions are made afresh on the new process, not resumed)."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

from std_msgs.msg import Int32

import roslibpy_lite
from roslibpy_lite.api import ConnectionState
from roslibpy_lite.bag import Recorder
from tests.bag.test_bag import _theirs
from tests.client.support import fast_backoff


async def test_a_bridge_restart_during_a_recording_goes_on_in_the_same_file(
    make_bridge: Any, ros_node: Any, topic: str, tmp_path: Path
) -> None:
    """The bridge is killed and started again on its port mid-recording: the recorder goes on
    in the one file once the client has reconnected (one gap in the stats and the file), no
    error; numbers from before and after the restart are in it, in order, each once."""
    bridge = make_bridge()
    pub = ros_node.create_publisher(Int32, topic, 100)
    path = tmp_path / "restart.mcap"
    sent = 0

    async def publish_until(count: int) -> None:
        """Publish the next numbers until the recording holds ``count`` of them."""
        nonlocal sent
        deadline = asyncio.get_running_loop().time() + 30
        while rec.stats.messages < count:
            assert asyncio.get_running_loop().time() < deadline, rec.stats
            pub.publish(Int32(data=sent))
            sent += 1
            await asyncio.sleep(0.05)  # the publishing rate

    async with (roslibpy_lite.connect(bridge.url, backoff=fast_backoff()) as ros,
                Recorder(ros, path, topics={topic: "std_msgs/msg/Int32"}) as rec):
        await publish_until(10)
        before = rec.stats.messages
        async with ros.state_changes() as changes:
            bridge.kill()
            while ros.state is not ConnectionState.RECONNECTING:
                await changes.next(30)
        await asyncio.to_thread(bridge.start)
        await ros.wait_connected(30)
        await publish_until(before + 10)
        recorded = rec.stats.messages
    stats = rec.stats
    assert stats.error is None and stats.files == [path], stats
    assert len(stats.gaps) == 1 and 0 < stats.gaps[0] < 30, stats.gaps
    numbers = [decoded.data for _, _, _, decoded in _theirs(path)]
    assert len(numbers) == recorded and numbers == sorted(set(numbers)), numbers
    assert numbers[0] < sent - 10 and numbers[-1] >= before  # both sides of the restart
