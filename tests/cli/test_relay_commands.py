"""The ros2-like commands through a relay URL, held to the token's role: an admin token gets a
parameter and a lifecycle state (and more), a viewer token's ``param set`` is refused with the
bridge's words and a non-zero exit, and the node's value stays."""

from __future__ import annotations

import asyncio
import json
import sys
from pathlib import Path
from typing import Any

import pytest

from tests.cli.ros2_nodes import full_name
from tests.relay.support import relay_with_auth

pytestmark = pytest.mark.timeout(120)

ROLES = """
[roles.viewer]
subscribe = ["*"]
introspection = ["*"]

[roles.admin]
all = ["*"]
"""


async def _cli(*argv: str) -> tuple[int, str, str]:
    """Run ``roslibpy-lite ARGV`` as its own process: (exit status, stdout, stderr)."""
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "roslibpy_lite.cli", *argv,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE)
    out, err = await proc.communicate()
    assert proc.returncode is not None
    return proc.returncode, out.decode(), err.decode()


async def test_param_and_lifecycle_through_a_relay_by_role(
    param_node: Any, managed_node: Any, tmp_path: Path, topic: str
) -> None:
    """Through the relay, for an admin token: param get/dump and lifecycle get/set print
    ros2's lines, service find finds, topic bw counts the robot's bytes; a viewer token's
    param set exits 6 with the bridge's refusal, the value unchanged."""
    from std_msgs.msg import String

    node, managed = full_name(param_node), full_name(managed_node)
    pub = param_node.create_publisher(String, topic, 10)
    param_node.create_timer(0.05, lambda: pub.publish(String(data="bytes")))
    async with relay_with_auth(tmp_path / "auth.toml", ROLES, robots=("robot1",)) as (
            relay, tokens):
        url = f"ws://127.0.0.1:{relay.port}/robot1"
        admin = ("--url", url, "--token", tokens["admin"])
        code, out, err = await _cli("param", "get", node, "count", "--wait", "30", *admin)
        assert (code, out) == (0, "Integer value is: 3\n"), err
        code, out, err = await _cli("lifecycle", "get", managed, "--wait", "30", *admin)
        assert (code, out) == (0, "unconfigured [1]\n"), err
        code, out, err = await _cli("lifecycle", "set", managed, "configure", *admin)
        assert (code, out) == (0, "Transitioning successful\n"), err
        code, out, err = await _cli("param", "dump", node, *admin)
        assert code == 0 and out.startswith(f"{node}:\n  ros__parameters:\n    count: 3\n"), err
        code, out, err = await _cli("service", "find", "lifecycle_msgs/srv/GetState", *admin)
        assert code == 0 and f"{managed}/get_state" in out.splitlines(), (out, err)
        code, out, err = await _cli("topic", "bw", topic, "--count", "3", "--json", "--wait", "30",
                                    *admin)
        assert code == 0 and json.loads(out.splitlines()[-1])["messages"] == 3, (out, err)
        viewer = ("--url", url, "--token", tokens["viewer"])
        code, out, err = await _cli("param", "set", node, "count", "8", *viewer)
        assert code == 6 and out == "", (code, out, err)
        assert err.startswith("roslibpy-lite: ") and "forbidden" in err, err
        assert "viewer" in err and f"{node}" in err, err
        code, out, err = await _cli("param", "set", node, "count", "8", *admin)
        assert (code, out) == (0, "Set parameter successful\n"), err
    assert param_node.get_parameter("count").value == 8
