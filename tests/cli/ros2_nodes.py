"""rclpy nodes for the ros2-like commands' tests: a node with parameters of every kind, and a
lifecycle (managed) node, spun by the test node's executor."""

from __future__ import annotations

import re
from collections.abc import Iterator
from typing import Any

import pytest

PARAMS: dict[str, Any] = {
    "count": 3,
    "name": "robot",
    "flags": [True, False],
    "gains": [0.5, 1.0],
    "nested.gain": 0.25,
}
"""The parameters :func:`param_node` declares (with ``speed_limit`` and ``scratch``)."""


def full_name(node: Any) -> str:
    """The node's fully qualified name."""
    ns = node.get_namespace().rstrip("/")
    return f"{ns}/{node.get_name()}"


@pytest.fixture
def param_node(ros_node: Any) -> Any:
    """The test's rclpy node with :data:`PARAMS`, ``speed_limit`` (a double in 0..10, step
    0.5, described, read only) and ``scratch`` (dynamically typed, so it may be deleted)."""
    from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor

    for name, value in PARAMS.items():
        ros_node.declare_parameter(name, value)
    ros_node.declare_parameter("speed_limit", 1.5, ParameterDescriptor(
        description="top speed", read_only=True,
        floating_point_range=[FloatingPointRange(from_value=0.0, to_value=10.0, step=0.5)]))
    ros_node.declare_parameter("scratch", "x", ParameterDescriptor(dynamic_typing=True))
    return ros_node


_serial = iter(range(1_000_000))


@pytest.fixture
def managed_node(ros_runtime: Any, ros_node: Any, request: pytest.FixtureRequest
                 ) -> Iterator[Any]:
    """An rclpy LifecycleNode (unconfigured), spun by the test node's executor, destroyed
    afterwards."""
    from rclpy.lifecycle import LifecycleNode

    name = "managed_" + re.sub(r"\W", "_", request.node.name)[:30] + f"_{next(_serial)}"
    node: Any = LifecycleNode(name, context=ros_runtime.context)
    executor = ros_node.executor
    executor.add_node(node)
    yield node
    executor.remove_node(node)
    node.destroy_node()
