"""``roslibpy-lite bag record`` through a relay (issue 26): the recorder is a client of the
relay like any other, and its MCAP holds the robot's messages with their schema."""

from __future__ import annotations

import asyncio
import sys
from pathlib import Path
from typing import Any

import pytest
from std_msgs.msg import String

from roslibpy_lite.bag import info, read
from tests.relay.support import tier

pytestmark = pytest.mark.timeout(90)


async def test_bag_record_through_a_relay(ros_node: Any, topic: str, tmp_path: Path) -> None:
    path = tmp_path / "through-relay.mcap"
    pub = ros_node.create_publisher(String, topic, 10)
    async with tier() as t:
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "roslibpy_lite.cli", "bag", "record", topic, "-o", str(path),
            "--max", "20", "-q", "--url", t.url(),
            stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE)
        n = 0
        deadline = asyncio.get_running_loop().time() + 60
        while proc.returncode is None:  # publish until the recorder has its 20 and ends
            n += 1
            pub.publish(String(data=f"recorded {n}"))
            try:
                await asyncio.wait_for(proc.wait(), 0.05)
            except TimeoutError:
                assert asyncio.get_running_loop().time() < deadline, "the recorder never ended"
        out, err = await proc.communicate()
    assert proc.returncode == 0, (out, err)
    about = info(path)
    assert about.complete and about.messages == 20
    assert about.topics[0].topic == topic and about.topics[0].type_name == "std_msgs/msg/String"
    texts = [m.decode().data for m in read(path)]  # type: ignore[attr-defined]
    assert all(text.startswith("recorded ") for text in texts)
    numbers = [int(text.split()[1]) for text in texts]
    assert numbers == sorted(numbers)  # in order, none twice
