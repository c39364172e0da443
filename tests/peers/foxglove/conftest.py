"""Fixtures of the stock Foxglove client tests: the module's client, and a bridge with an auth file."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import BridgeProcess
from tests.peers.peer import PeerPool, PeerProcess
from tests.security.support import make_auth_file


@pytest.fixture
def fox(peer_pool: PeerPool) -> PeerProcess:
    """The module's connected Foxglove client, ready for this test."""
    return peer_pool.get("foxglove")


@pytest.fixture(scope="module")
def secured(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[BridgeProcess, Any]]:
    """A bridge with an auth file and a small message size limit."""
    tmp: Path = tmp_path_factory.mktemp("foxglove_auth")
    auth = make_auth_file(tmp)
    proc = BridgeProcess(args=["--auth-file", str(auth.path), "--max-message-size", "65536",
                               "--max-publishers", "2"])
    proc.start()
    yield proc, auth
    proc.stop()
