"""Jazzy and Kilted on one DDS graph: this venv's bridge and a plain rclpy node run by the other
distribution's venv (tests/distro/echo_peer.py) exchange topics, a service and images.

Run from either venv: in the Jazzy run (.venv) the peer is Kilted's, in the Kilted leg
(.venv-kilted, scripts/test.sh under CI) it is Jazzy's. See docs/distributions.md.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import pytest

from roslibpy_lite.exceptions import ServiceError
from tests.distro.support import (
    answered,
    echo_peer,
    heard,
    other_distro,
    other_env,
    other_python,
    this_distro,
)

if TYPE_CHECKING:
    from roslibpy_lite import Client


async def test_other_distributions_node_and_this_bridge_share_a_graph(
        client: Client, topic: str) -> None:
    """A String published through this bridge reaches the other distribution's node and its
    echo comes back, its SetBool service answers through the bridge, and its Image arrives
    whole: Fast DDS 2.14 (Jazzy) and 3.x (Kilted) interoperate on one domain."""
    peer, distro = echo_peer(other_python(), topic, other_env())
    try:
        assert distro == other_distro()
        assert await heard(client, topic, "hello") == {"data": f"{distro}:hello"}
        assert await answered(client, f"{topic}/srv") == {"success": True, "message": distro}
        async with client.subscribe(f"{topic}/image", "sensor_msgs/msg/Image") as images:
            frame = await images.get(15)
        assert (frame["header"]["frame_id"], frame["width"], frame["height"]) == (distro, 3, 2)
        assert bytes(frame["data"]) == bytes(range(6))
    finally:
        peer.stop()


async def test_a_type_only_kilted_has_is_known_to_a_kilted_bridge_alone(client: Client) -> None:
    """The limit of a mixed graph: a bridge knows the types its distribution installs. Kilted's
    keyed test message is described by a Kilted bridge and refused by name by a Jazzy one."""
    details = client.call_service("/rosapi/message_details", "rosapi_msgs/srv/MessageDetails",
                                  {"type": "test_msgs/msg/KeyedString"}, timeout=15)
    if this_distro() == "kilted":
        assert (await details)["typedefs"][0]["fieldnames"] == ["key", "value"]
    else:
        with pytest.raises(ServiceError, match="unknown type 'test_msgs/msg/KeyedString'"):
            await details
