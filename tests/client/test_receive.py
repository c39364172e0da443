"""The client's receive path without a network: frames in, deliveries out."""

from __future__ import annotations

import asyncio
import json
import logging
from typing import Any

import cbor2
import pytest

from msgs.std_msgs.msg import Float32MultiArray, String
from rosbridge_core.protocol.frames import split_fragments
from roslibpy_lite import Client, RosTimeoutError, StatusError


def _pub(topic: str, msg: dict[str, Any]) -> str:
    return json.dumps({"op": "publish", "topic": topic, "msg": msg})


@pytest.fixture
async def client() -> Any:
    """A client that was never connected: handles register, frames are fed by hand."""
    c = Client("ws://127.0.0.1:9")
    yield c
    await c.close()


async def test_publish_reaches_subscriptions_of_its_topic_only(client: Client) -> None:
    """A publish frame goes to every subscription of its topic and to no other."""
    a = client.subscribe("/a", "std_msgs/msg/String")
    a2 = client.subscribe("/a", "std_msgs/String")
    b = client.subscribe("/b", "std_msgs/msg/String")
    client._receive(_pub("/a", {"data": "x"}))
    assert await a.get(1) == {"data": "x"}
    assert await a2.get(1) == {"data": "x"}
    assert b.pending == 0 and b.received == 0


async def test_typed_subscription_yields_instances(client: Client) -> None:
    """A subscription made with a msgs class yields instances of it."""
    sub = client.subscribe("/s", String)
    client._receive(_pub("/s", {"data": "typed"}))
    msg = await sub.get(1)
    assert isinstance(msg, String) and msg.data == "typed"


async def test_typed_subscription_skips_messages_that_do_not_fit(
    client: Client, caplog: pytest.LogCaptureFixture
) -> None:
    """A message that does not fit the class is counted, logged without payload, and skipped."""
    sub = client.subscribe("/s", String)
    with caplog.at_level(logging.WARNING, "roslibpy_lite.client"):
        client._receive(_pub("/s", {"data": 5}))
    client._receive(_pub("/s", {"data": "ok"}))
    assert (await sub.get(1)).data == "ok"
    assert sub.decode_errors == 1
    assert "data" in caplog.text


async def test_buffer_drops_oldest_and_counts(client: Client) -> None:
    """A full buffer drops its oldest message and counts the drop."""
    sub = client.subscribe("/q", "std_msgs/msg/Int32", buffer_size=3)
    for i in range(5):
        client._receive(_pub("/q", {"data": i}))
    assert sub.dropped == 2 and sub.received == 5
    assert [(await sub.get(1))["data"] for _ in range(3)] == [2, 3, 4]


async def test_iteration_waits_for_the_next_message(client: Client) -> None:
    """``async for`` wakes when a message arrives later."""
    sub = client.subscribe("/w", "std_msgs/msg/Int32")

    async def first() -> Any:
        async for msg in sub:
            return msg
        return None

    task = asyncio.create_task(first())
    await asyncio.sleep(0)
    assert not task.done()
    client._receive(_pub("/w", {"data": 9}))
    assert await asyncio.wait_for(task, 1) == {"data": 9}


async def test_get_times_out(client: Client) -> None:
    """``get`` with a timeout raises RosTimeoutError when nothing arrives."""
    sub = client.subscribe("/none", "std_msgs/msg/Int32")
    with pytest.raises(RosTimeoutError, match="/none"):
        await sub.get(0.05)


async def test_sync_callback_runs_inline_in_order(client: Client) -> None:
    """Sync callbacks run at once, in arrival order, and nothing is buffered."""
    got: list[int] = []
    sub = client.subscribe("/cb", "std_msgs/msg/Int32", callback=lambda m: got.append(m["data"]))
    for i in range(3):
        client._receive(_pub("/cb", {"data": i}))
    assert got == [0, 1, 2]
    assert sub.pending == 0


async def test_async_callback_runs_in_order(client: Client) -> None:
    """An async callback gets every message in order, one at a time."""
    got: list[int] = []
    done = asyncio.Event()

    async def cb(msg: dict[str, Any]) -> None:
        await asyncio.sleep(0)
        got.append(msg["data"])
        if len(got) == 4:
            done.set()

    client.subscribe("/acb", "std_msgs/msg/Int32", cb)
    for i in range(4):
        client._receive(_pub("/acb", {"data": i}))
    await asyncio.wait_for(done.wait(), 2)
    assert got == [0, 1, 2, 3]


async def test_callback_errors_are_counted_not_fatal(client: Client) -> None:
    """A raising callback is logged and counted; later messages still arrive."""
    seen: list[int] = []

    def cb(msg: dict[str, Any]) -> None:
        if msg["data"] == 0:
            raise RuntimeError("boom")
        seen.append(msg["data"])

    sub = client.subscribe("/err", "std_msgs/msg/Int32")
    sub.on_message(cb)
    client._receive(_pub("/err", {"data": 0}))
    client._receive(_pub("/err", {"data": 1}))
    assert seen == [1] and sub.callback_errors == 1


async def test_a_failing_callback_is_logged_once_per_burst_then_paused(
        client: Client, caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch) -> None:
    """Outside Jupyter a callback raising on every message logs one traceback, then one line
    with the count; after PAUSE_AFTER in a row it is paused, and resume_callbacks() runs it."""
    from roslibpy_lite.handles.subscription import callbacks

    monkeypatch.setattr(callbacks, "PAUSE_AFTER", 30)
    calls: list[int] = []

    def cb(msg: dict[str, Any]) -> None:
        calls.append(msg["data"])
        raise ValueError(f"bad {msg['data']}")

    sub = client.subscribe("/burst", "std_msgs/msg/Int32", cb)
    with caplog.at_level(logging.INFO, logger="roslibpy_lite"):
        for i in range(20):
            client._receive(_pub("/burst", {"data": i}))
        assert [r.exc_info is not None for r in caplog.records] == [True]
        for i in range(20, 40):
            client._receive(_pub("/burst", {"data": i}))
        assert len(calls) == 30 and sub.paused == [cb] and sub.callback_errors == 30
        texts = [r.getMessage() for r in caplog.records]
        assert texts[1].endswith("raised 29 more times in the last 0.0 s (the last: "
                                 "ValueError: bad 29)"), texts
        assert "raised 30 times in a row: paused (sub.resume_callbacks()" in texts[2], texts
        assert len(texts) == 3
        assert sub.resume_callbacks() == 1
        client._receive(_pub("/burst", {"data": 99}))
    assert calls[-1] == 99 and sub.paused == []


async def test_fragments_are_reassembled(client: Client) -> None:
    """A publish split into fragments arrives once, whole."""
    sub = client.subscribe("/frag", "std_msgs/msg/String")
    text = _pub("/frag", {"data": "y" * 500})
    pieces = split_fragments(text, 64, "f1")
    assert len(pieces) > 2
    for piece in reversed(pieces):
        client._receive(piece)
    assert (await sub.get(1))["data"] == "y" * 500
    assert sub.received == 1


async def test_cbor_frames_with_typed_arrays_decode(client: Client) -> None:
    """A binary CBOR frame with an RFC 8746 float32 array decodes into numbers."""
    import array

    sub = client.subscribe("/cbor", Float32MultiArray, compression="cbor")
    payload = array.array("f", [1.5, -2.0, 3.25]).tobytes()
    frame = cbor2.dumps({
        "op": "publish", "topic": "/cbor",
        "msg": {"layout": {"dim": [], "data_offset": 0}, "data": cbor2.CBORTag(85, payload)},
    })
    client._receive(frame)
    msg = await sub.get(1)
    assert msg.data == [1.5, -2.0, 3.25]


async def test_bad_frames_are_ignored_and_logged(
    client: Client, caplog: pytest.LogCaptureFixture
) -> None:
    """Malformed JSON and unknown ops are logged and do not disturb later frames."""
    sub = client.subscribe("/ok", "std_msgs/msg/Int32")
    with caplog.at_level(logging.WARNING, "roslibpy_lite.client"):
        client._receive("{not json")
        client._receive(json.dumps({"op": "bogus"}))
        client._receive(json.dumps({"op": "publish", "topic": "/ok"}))
    client._receive(_pub("/ok", {"data": 1}))
    assert await sub.get(1) == {"data": 1}
    assert "malformed JSON" in caplog.text and "bogus" in caplog.text and "msg" in caplog.text


async def test_status_error_for_a_subscribe_fails_its_iteration(client: Client) -> None:
    """A status error naming a subscription's id is raised from its iteration."""
    sub = client.subscribe("/bad", "nope_msgs/msg/Nope")
    client._receive(json.dumps({"op": "status", "level": "error", "msg": "unknown type",
                                "id": sub.id}))
    with pytest.raises(StatusError, match="unknown type"):
        await sub.get(1)


async def test_status_error_for_an_advertise_fails_the_next_publish(client: Client) -> None:
    """A status error naming a publisher's advertise is raised by its next publish."""
    pub = client.advertise("/p", "nope_msgs/msg/Nope")
    client._receive(json.dumps({"op": "status", "level": "error", "msg": "no such type",
                                "id": pub.id}))
    with pytest.raises(StatusError, match="no such type"):
        await pub.publish({})


async def test_unsubscribed_subscription_gets_nothing_more(client: Client) -> None:
    """After unsubscribe, publishes on the topic are not delivered and iteration ends."""
    sub = client.subscribe("/u", "std_msgs/msg/Int32")
    client._receive(_pub("/u", {"data": 1}))
    await sub.unsubscribe()
    client._receive(_pub("/u", {"data": 2}))
    assert [m async for m in sub] == [{"data": 1}]
    assert sub.received == 1
