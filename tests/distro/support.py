"""The other ROS 2 distribution's venv, for tests that put Jazzy and Kilted side by side.

The repository's set-up makes one venv per distribution (scripts/setup.sh: ``.venv`` for
Jazzy, ``.venv-kilted`` for Kilted); a test run in one of them starts ROS programs with the
other's Python. Each venv's ROS wheels are found through ``LD_LIBRARY_PATH``, which their
bootstrapper sets once and marks done (``_ROS_WHEELS_BOOTSTRAP_COMPLETE``); a child of this
(bootstrapped) process would inherit both and load this distribution's libraries, so
:func:`other_env` drops them.
"""

from __future__ import annotations

import asyncio
import os
import re
import sys
from importlib.metadata import version
from typing import TYPE_CHECKING, Any

import pytest

from roslibpy_lite.exceptions import RosTimeoutError, ServiceError
from tests.helpers import ROOT, ros_env, send_until_heard
from tests.relay.procs import Proc

if TYPE_CHECKING:
    from roslibpy_lite import Client

VENVS = {"jazzy": ROOT / ".venv", "kilted": ROOT / ".venv-kilted"}
"""Where scripts/setup.sh makes each distribution's venv."""

RCLPY_MAJOR = {"7": "jazzy", "9": "kilted"}
"""rclpy's major version in each distribution's wheels (ros-rclpy 7.1.6, 9.1.2)."""

READY = re.compile(r"echo peer ready (\w+) ([\d.]+)")


def this_distro() -> str:
    """The distribution of the venv running the tests (by its rclpy)."""
    return RCLPY_MAJOR.get(version("ros-rclpy").split(".")[0], "unknown")


def other_distro() -> str:
    """The distribution the mixed tests pair with this one."""
    return "kilted" if this_distro() == "jazzy" else "jazzy"


def other_python() -> str:
    """The other distribution's venv Python; the test is skipped (a failure under CI) when
    that venv was not made."""
    distro = other_distro()
    python = VENVS[distro] / "bin" / "python"
    if not python.exists():
        flag = "ROS_DISTRO=kilted " if distro == "kilted" else ""
        pytest.skip(f"no {distro} venv at {python.parent.parent} "
                    f"(make it with: {flag}bash scripts/setup.sh)")
    return str(python)


def other_env(**extra: str) -> dict[str, str]:
    """:func:`tests.helpers.ros_env` for a child run by the other venv's Python: without
    this venv's library path and bootstrap mark, so that its own bootstrapper sets them."""
    env = ros_env(**extra)
    env.pop("_ROS_WHEELS_BOOTSTRAP_COMPLETE", None)
    mine = sys.prefix + os.sep
    kept = [p for p in env.get("LD_LIBRARY_PATH", "").split(os.pathsep)
            if p and not os.path.realpath(p).startswith(os.path.realpath(mine))
            and not p.startswith(mine)]
    env["LD_LIBRARY_PATH"] = os.pathsep.join(kept)
    env.pop("VIRTUAL_ENV", None)
    return env


def echo_peer(python: str, prefix: str, env: dict[str, str]) -> tuple[Proc, str]:
    """Start :mod:`tests.distro.echo_peer` with ``python``; returns it once ready, with the
    distribution it reported."""
    peer = Proc([python, "-m", "tests.distro.echo_peer", prefix], env)
    distro = peer.wait_for(READY, timeout=60).group(1)
    return peer, distro


def bridge_command(python: str, *args: str) -> list[str]:
    """``python -m bridge_server`` on 127.0.0.1 with ``args``."""
    return [python, "-m", "bridge_server", "--host", "127.0.0.1", *args]

async def heard(client: Client, topic: str, data: str, timeout: float = 30.0) -> Any:
    """Publish ``data`` on ``topic/in`` until an answer comes on ``topic/out`` (DDS discovery
    across the two processes has no event to await)."""
    async with client.advertise(f"{topic}/in", "std_msgs/msg/String") as pub, \
            client.subscribe(f"{topic}/out", "std_msgs/msg/String") as sub:
        return await send_until_heard(lambda: pub.publish({"data": data}), sub.get,
                                      f"an answer on {topic}/out", attempt=0.5, timeout=timeout)


async def answered(client: Client, service: str, timeout: float = 30.0) -> Any:
    """Call ``service`` (std_srvs/SetBool) until it is there and answers."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while True:
        try:
            return await client.call_service(service, "std_srvs/srv/SetBool", {"data": True},
                                             timeout=5)
        except (ServiceError, RosTimeoutError):
            if loop.time() > deadline:
                raise
            await asyncio.sleep(0.3)  # not yet discovered: the bridge said so at once


__all__ = ["VENVS", "answered", "bridge_command", "echo_peer", "heard", "other_distro", "other_env", "other_python",
           "this_distro"]
