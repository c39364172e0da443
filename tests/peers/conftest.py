"""Fixtures for the peer tests: stock clients in child processes, connected to the session bridge."""

from __future__ import annotations

import importlib
import re
import warnings
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from tests.helpers import BridgeProcess, spun_node
from tests.peers.peer import PeerPool, PeerProcess

# rclpy's type support imports lark, which imports the deprecated sre_parse; with
# warnings as errors that would fail the first rclpy node made here. Import it once,
# quietly (the same work-around as tests/bridge/convert_support.py; see the report to the lead).
with warnings.catch_warnings():
    warnings.filterwarnings("ignore", "module 'sre_.*' is deprecated", DeprecationWarning)
    importlib.import_module("rosidl_generator_py")

@pytest.fixture(scope="module")
def peer_pool(bridge: BridgeProcess) -> Iterator[PeerPool]:
    """Stock clients shared by the tests of one module; all closed at its end."""
    pool = PeerPool(bridge)
    yield pool
    pool.close()


@pytest.fixture
def start_peer(peer_pool: PeerPool) -> Iterator[Callable[..., PeerProcess]]:
    """Start private stock clients for one test; they are closed after it.

    ``start_peer("roslibpy")``, ``start_peer("roslib")`` (Node, with the ``ws``
    package) or ``start_peer("roslib", native_websocket=True)`` (Node's own
    WebSocket).
    """
    started: list[PeerProcess] = []

    def start(kind: str, native_websocket: bool = False) -> PeerProcess:
        peer = peer_pool.start(kind, native_websocket)
        started.append(peer)
        return peer

    yield start
    for peer in started:
        peer.close()


@pytest.fixture(scope="module")
def module_node(ros_runtime: Any, request: pytest.FixtureRequest) -> Iterator[Any]:
    """One rclpy node for the whole module, spun by its own executor thread.

    Destroying an rclpy node delays the process's discovery of new remote
    endpoints by up to ~3 s (Fast DDS, reproduced with two plain rclpy
    processes, no bridge involved); destroying publishers, subscriptions and
    services does not. So the peer tests keep one node and clean up entities.
    """
    name = "peers_" + re.sub(r"\W", "_", request.module.__name__.rsplit(".", 1)[-1])
    # Nothing may stop the spinning that every later test of the module needs; what a
    # round raises fails the test during which it happened (see ros_node).
    with spun_node(ros_runtime.rclpy, ros_runtime.context, name) as (node, errors):
        node.spin_errors = errors
        yield node


@pytest.fixture
def ros_node(module_node: Any) -> Iterator[Any]:
    """The module's rclpy node; what a test creates on it is destroyed after the test.

    Overrides the suite-wide ``ros_node`` (a fresh node per test) for the reason
    given in :func:`module_node`.
    """
    node = module_node
    kinds = (
        ("publishers", node.destroy_publisher),
        ("subscriptions", node.destroy_subscription),
        ("services", node.destroy_service),
        ("clients", node.destroy_client),
        ("timers", node.destroy_timer),
    )
    before = {kind: set(getattr(node, kind)) for kind, _ in kinds}
    errors: list[str] = node.spin_errors
    seen = len(errors)
    yield node
    for kind, destroy in kinds:
        for entity in set(getattr(node, kind)) - before[kind]:
            destroy(entity)
    if len(errors) > seen:
        pytest.fail("the module's rclpy executor raised during this test:\n" + errors[-1])
