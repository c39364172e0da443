"""The two backends every conformance test runs against: MockRos and the client on the real bridge."""

from __future__ import annotations

from collections.abc import AsyncIterator

import pytest

import roslibpy_lite
from roslibpy_lite import MockRos, Ros


@pytest.fixture(params=["mock", "bridge"])
async def ros(request: pytest.FixtureRequest) -> AsyncIterator[Ros]:
    """A connected backend: MockRos, or the websocket client on the session's bridge."""
    if request.param == "mock":
        async with MockRos() as mock:
            yield mock
        return
    bridge = request.getfixturevalue("bridge")
    async with roslibpy_lite.connect(bridge.url) as client:
        yield client


@pytest.fixture
def backend(ros: Ros) -> str:
    """The name of the backend under test."""
    return "mock" if isinstance(ros, MockRos) else "bridge"
