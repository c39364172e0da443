"""Our bridge's ``status`` errors reach the request that caused them (a stock server sends none)."""

from __future__ import annotations

import asyncio

import pytest

from roslibpy_lite import Client, RemoteError, StatusError


async def test_refused_subscribe_fails_its_iteration(client: Client, topic: str) -> None:
    """Subscribing with an unknown type: iterating the subscription raises StatusError naming it."""
    sub = client.subscribe(topic, "nope_msgs/msg/Nothing")
    with pytest.raises(StatusError, match="nope_msgs") as info:
        await sub.get(15)
    assert info.value.id == sub.id


async def test_refused_advertise_fails_later_publishes(client: Client, topic: str) -> None:
    """Advertising an unknown type: once the bridge's error arrives, publish raises StatusError."""
    refused = asyncio.Event()
    pub = client.advertise(topic, "nope_msgs/msg/Nothing")
    client.on_status(lambda op: refused.set() if op.id == pub.id else None)
    await asyncio.wait_for(refused.wait(), 15)
    with pytest.raises(StatusError, match="nope_msgs"):
        await pub.publish({})


async def test_call_with_unknown_type_is_a_remote_error(client: Client, topic: str) -> None:
    """A call naming an unknown service type fails at once with a remote error naming the type."""
    with pytest.raises(RemoteError, match="nope_msgs"):
        await client.call_service(topic, "nope_msgs/srv/Nothing", {}, timeout=15)
