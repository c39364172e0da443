"""A mixed fleet: a Jazzy robot and a Kilted robot behind one relay. Each robot is a bridge
process dialing out to the relay (--zenoh-connect), run by its distribution's venv, with a
plain rclpy node of the same distribution on its own DDS domain (tests/distro/echo_peer.py);
a client reaches both through the relay's one port. See docs/distributions.md.
"""

from __future__ import annotations

import contextlib
import os
import sys

import roslibpy_lite
from tests.distro.support import (
    answered,
    bridge_command,
    echo_peer,
    heard,
    other_distro,
    other_env,
    other_python,
    this_distro,
)
from tests.helpers import ros_env
from tests.relay.procs import Proc
from tests.relay.support import free_port, robot_reachable, start_relay


async def test_a_jazzy_and_a_kilted_robot_behind_one_relay(topic: str) -> None:
    """Through one relay, each robot's own ROS node echoes a String and answers its service
    with its distribution's name: the relay (no ROS) serves robots of both distributions."""
    other = other_python()
    domain = int(os.environ["ROS_DOMAIN_ID"])
    # name -> (Python, environment): each robot on a DDS domain of its own
    robots = {
        this_distro(): (sys.executable, ros_env()),
        other_distro(): (other, other_env(ROS_DOMAIN_ID=str((domain + 100) % 200))),
    }
    router = f"tcp/127.0.0.1:{free_port()}"
    relay = await start_relay(listen=router)
    procs: list[Proc] = []
    try:
        for name, (python, env) in robots.items():
            peer, distro = echo_peer(python, topic, env)
            procs.append(peer)
            assert distro == name
            procs.append(Proc(bridge_command(python, "--no-websocket", "--zenoh-connect", router,
                                             "--robot", name), env))
        for name in robots:
            await robot_reachable(relay, name, timeout=60)
        for name in robots:
            async with roslibpy_lite.connect(f"ws://127.0.0.1:{relay.port}/{name}") as ros:
                assert await heard(ros, topic, "via relay") == {"data": f"{name}:via relay"}
                assert await answered(ros, f"{topic}/srv") == {"success": True, "message": name}
    finally:
        for proc in reversed(procs):
            with contextlib.suppress(Exception):
                proc.stop()
        await relay.close()
