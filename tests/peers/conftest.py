"""Fixtures for the peer tests: stock clients in child processes, connected to the session bridge."""

from __future__ import annotations

import importlib
import shutil
import sys
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from tests.helpers import BridgeProcess
from tests.peers.peer import PeerProcess

# rclpy's type support imports lark, which imports the deprecated sre_parse; with
# warnings as errors that would fail the first rclpy node made here. Import it once,
# quietly (the same work-around as tests/bridge/test_convert.py; see the report to the lead).
with warnings.catch_warnings():
    warnings.filterwarnings("ignore", "module 'sre_.*' is deprecated", DeprecationWarning)
    importlib.import_module("rosidl_generator_py")

PEERS = Path(__file__).resolve().parent
NODE_DIR = PEERS / "node"


def _node_argv(url: str, native_websocket: bool) -> list[str]:
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not on PATH: the roslib (npm) peer tests need Node.js 20+")
    if not (NODE_DIR / "node_modules" / "roslib" / "package.json").is_file():
        pytest.fail(
            "tests/peers/node/node_modules has no roslib: run scripts/setup.sh "
            "(or `npm ci` in tests/peers/node)",
            pytrace=False,
        )
    flags = ["--experimental-websocket"] if native_websocket else []
    return [node, *flags, str(NODE_DIR / "peer.mjs"), url]


@pytest.fixture
def start_peer(bridge: BridgeProcess) -> Iterator[Callable[..., PeerProcess]]:
    """Start stock clients against the session bridge; all are closed after the test.

    ``start_peer("roslibpy")``, ``start_peer("roslib")`` (Node, with the ``ws``
    package) or ``start_peer("roslib", native_websocket=True)`` (Node's own
    WebSocket).
    """
    started: list[PeerProcess] = []

    def start(kind: str, native_websocket: bool = False) -> PeerProcess:
        if kind == "roslibpy":
            argv = [sys.executable, str(PEERS / "roslibpy_peer.py"), "127.0.0.1", str(bridge.port)]
            name = "roslibpy"
        elif kind == "roslib":
            argv = _node_argv(bridge.url, native_websocket)
            name = "roslib-native" if native_websocket else "roslib-ws"
        else:
            raise ValueError(kind)
        peer = PeerProcess(name, argv, PEERS)
        started.append(peer)
        return peer.start()

    yield start
    for peer in started:
        peer.close()
