"""The two backends the blocking client's tests run against: sync.MockRos and sync.connect on the bridge."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from roslibpy_lite import sync


@pytest.fixture(params=["mock", "bridge"])
def ros(request: pytest.FixtureRequest) -> Iterator[sync.Client | sync.MockRos]:
    """A connected blocking backend: sync.MockRos, or sync.connect on the session's bridge."""
    if request.param == "mock":
        with sync.MockRos() as mock:
            yield mock
        return
    bridge = request.getfixturevalue("bridge")
    with sync.connect(bridge.url) as client:
        yield client
