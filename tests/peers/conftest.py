"""Fixtures for the peer tests: stock clients in child processes, connected to the session bridge."""

from __future__ import annotations

import importlib
import warnings
from collections.abc import Callable, Iterator

import pytest

from tests.helpers import BridgeProcess
from tests.peers.peer import PeerPool, PeerProcess

# rclpy's type support imports lark, which imports the deprecated sre_parse; with
# warnings as errors that would fail the first rclpy node made here. Import it once,
# quietly (the same work-around as tests/bridge/test_convert.py; see the report to the lead).
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
