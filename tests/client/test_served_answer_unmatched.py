"""A ROS caller of a client-served service whose reply reader the bridge has not matched:
rmw_fastrtps waits 100 ms for the match, then drops the answer ("client will not receive
response", a RuntimeWarning in rclpy). rclpy's wait_for_service is true once the caller's
side is matched, even while the bridge is frozen, so a caller that calls at once on a loaded
machine hit this (issue 43: the first call to a just-created service got no answer). The
bridge sends the answer again while the match may still come, and says so when it never
does."""

from __future__ import annotations

import asyncio
import contextlib
import time
import warnings
from collections.abc import Callable
from typing import Any

import pytest

import roslibpy_lite
from tests.helpers import BridgeProcess

# rclpy's type support imports lark, which imports the deprecated sre_parse (warnings are errors).
with warnings.catch_warnings():
    warnings.simplefilter("ignore", DeprecationWarning)
    import rosidl_generator_py  # noqa: F401

from mult_msgs.srv import MultFloats as RosMultFloats
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from bridge_server.rclpy_graph.served import ANSWER_RETRIES


@pytest.mark.parametrize("reader", ["auto", "thread"])
async def test_an_answer_the_middleware_drops_is_sent_again_then_reported(
        make_bridge: Callable[..., BridgeProcess], ros_node: Any, topic: str,
        reader: str) -> None:
    """A caller whose reply reader can never match (it asks transient-local of the volatile
    reply writer): the client answers its request, the bridge tries the answer 7 times over
    6.3 s and then logs a warning naming the service, with either topic reader."""
    bridge = make_bridge("--topic-reader", reader)
    asked = asyncio.Event()

    def serve(request: dict[str, Any]) -> dict[str, Any]:
        asked.set()
        return {"result": request["x"] * request["y"]}

    async with roslibpy_lite.connect(bridge.url) as client:
        await client.advertise_service(topic, "mult_msgs/srv/MultFloats", serve)
        unmatched = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,  # type: ignore[no-untyped-call]
                               durability=DurabilityPolicy.TRANSIENT_LOCAL)
        caller = ros_node.create_client(RosMultFloats, topic, qos_profile=unmatched)
        futures = []
        try:
            # calls until one reaches the bridge: the caller's request writer matches on its
            # own time, and service_is_ready() stays false (the reply reader never matches)
            while not asked.is_set():
                futures.append(caller.call_async(RosMultFloats.Request(x=3.0, y=2.0)))
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(asked.wait(), 0.2)
            started = time.monotonic()
            line = await asyncio.to_thread(
                bridge.wait_for_line, rf"could not answer a ROS caller of {topic}: its reply "
                r"reader never matched", 30)
            assert time.monotonic() - started >= sum(ANSWER_RETRIES) - 0.2
            assert f"({len(ANSWER_RETRIES) + 1} tries over " in line
            assert not any(f.done() for f in futures)
        finally:
            for future in futures:
                caller.remove_pending_request(future)
