"""The robot's own types on a machine without them: definitions from the real bridge, typed
classes built here, raw subscriptions with the robot's CDR bytes; MockRos with the same types."""

from __future__ import annotations

import time
from typing import Any

import pytest
from rclpy.serialization import deserialize_message
from robot_msgs.msg import Status as RosStatus
from robot_msgs.msg import Wheel as RosWheel

import roslibpy_lite
from msgs.runtime import Message
from roslibpy_lite import Client, MockRos, RawMessage, ServiceError, UsageError
from tests.client.test_bridge_formats import first_message
from tests.msgs.test_dynamic import _definition


def _ros_status() -> RosStatus:
    msg = RosStatus(mode=RosStatus.MODE_DRIVE, label="r2", battery_cells=[3.5, 3.25],
                    blob=b"\x00\xffabc")
    msg.header.frame_id = "base"
    msg.wheels = [RosWheel(name="left", speed=0.5, ticks=[1, 2, 3])]
    msg.pose.position.x = 2.0
    return msg


def _check(msg: Any) -> None:
    assert (msg.mode, msg.label, msg.header.frame_id) == (1, "r2", "base")
    assert list(msg.battery_cells) == [3.5, 3.25] and bytes(msg.blob) == b"\x00\xffabc"
    wheel = msg.wheels[0]
    assert (wheel.name, list(wheel.ticks), msg.pose.position.x) == ("left", [1, 2, 3], 2.0)


@pytest.mark.parametrize("compression", ["none", "cbor-raw"])
async def test_load_types_from_the_bridge_then_subscribe_typed(
    client: Client, ros_node: Any, topic: str, compression: str
) -> None:
    """robot_msgs is not in msgs: load_types asks the bridge, and a typed subscription (JSON,
    or the robot's CDR decoded here) gets what rclpy published."""
    [status] = await client.load_types("robot_msgs/msg/Status")
    assert isinstance(status, type) and issubclass(status, Message)
    pub = ros_node.create_publisher(RosStatus, topic, 10)
    async with client.subscribe(topic, status, compression=compression) as sub:
        msg = await first_message(lambda: pub.publish(_ros_status()), sub)
    assert isinstance(msg, status)
    _check(msg)


async def test_a_loaded_type_publishes_typed_and_is_checked_at_the_call(
    client: Client, ros_node: Any, topic: str
) -> None:
    """A typed publisher of a loaded type reaches rclpy; a wrong field fails at the call."""
    [status] = await client.load_types("robot_msgs/Status")
    assert issubclass(status, Message)
    got: list[RosStatus] = []
    ros_node.create_subscription(RosStatus, topic, got.append, 10)
    pub = await client.advertise(topic, status)
    with pytest.raises(roslibpy_lite.InvalidMessageError, match="label"):
        await pub.publish({"label": "far too long for sixteen"})
    sent = status.from_json({"mode": 1, "label": "r2", "header": {"frame_id": "base"},
                             "battery_cells": [3.5, 3.25], "blob": b"\x00\xffabc",
                             "wheels": [{"name": "left", "speed": 0.5, "ticks": [1, 2, 3]}],
                             "pose": {"position": {"x": 2.0}}})
    deadline = time.monotonic() + 15
    while not got and time.monotonic() < deadline:  # discovery has no event to await
        await pub.publish(sent)
        await client.call_service("/rosapi/get_time", "rosapi_msgs/srv/GetTime")
    assert got
    _check(got[0])


async def test_raw_subscription_hands_out_the_robots_bytes_and_stamp(
    client: Client, ros_node: Any, topic: str
) -> None:
    """raw=True: RawMessage with CDR that rclpy reads back, and the bridge's stamp; decode()
    gives the typed message once the type is loaded."""
    before = time.time_ns()
    pub = ros_node.create_publisher(RosStatus, topic, 10)
    async with client.subscribe(topic, "robot_msgs/msg/Status", raw=True) as sub:
        raw = await first_message(lambda: pub.publish(_ros_status()), sub)
    assert isinstance(raw, RawMessage)
    assert (raw.topic, raw.type_name) == (topic, "robot_msgs/msg/Status")
    assert deserialize_message(raw.data, RosStatus) == _ros_status()
    assert before <= raw.stamp_ns <= time.time_ns()
    assert "bytes>" in repr(raw) and str(raw.data[:4]) not in repr(raw)
    await client.load_types("robot_msgs/msg/Status")
    _check(raw.decode())
    with pytest.raises(UsageError, match="raw=True"):
        client.subscribe(topic, "robot_msgs/msg/Status", raw=True, compression="cbor")


async def test_an_unknown_type_is_a_clear_error(client: Client) -> None:
    """A type the robot does not have: the bridge's answer names it."""
    with pytest.raises(ServiceError, match="nope_msgs/msg/Missing is not installed"):
        await client.load_types("nope_msgs/msg/Missing")


async def test_mockros_checks_a_defined_type_and_serves_raw_subscriptions() -> None:
    """define_type makes a robot type known to MockRos: bad fields fail as on the bridge, and
    a raw subscription gets CDR (serialized here) that decodes to what was published."""
    roslibpy_lite.define_type("robot_msgs/msg/Status", _definition("robot_msgs/msg/Status"))
    async with MockRos() as ros:
        sub = await ros.subscribe("/status", "robot_msgs/msg/Status", raw=True)
        pub = await ros.advertise("/status", "robot_msgs/msg/Status")
        with pytest.raises(roslibpy_lite.InvalidMessageError, match="wheels"):
            await pub.publish({"wheels": [{"ticks": "not a list"}]})
        with pytest.warns(roslibpy_lite.PartialMessageWarning,  # the defaults, said once
                          match="lacks header.stamp, pose.position.y"):
            await pub.publish({"mode": 1, "label": "r2", "header": {"frame_id": "base"},
                               "battery_cells": [3.5, 3.25], "blob": list(b"\x00\xffabc"),
                               "wheels": [{"name": "left", "speed": 0.5, "ticks": [1, 2, 3]}],
                               "pose": {"position": {"x": 2.0}}})
        raw = await sub.get(5)
    assert isinstance(raw, RawMessage)
    _check(raw.decode())
    assert deserialize_message(raw.data, RosStatus) == _ros_status()
