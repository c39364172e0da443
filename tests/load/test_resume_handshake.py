"""The bridge's side of the resume handshake, on the wire: a received count that is malformed
or more than the session sent is refused with HTTP 400 and one line naming the header and the
problem, before the session is touched; the session then resumes with a correct count."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest
from std_msgs.msg import Int32
from websockets.asyncio.client import connect as ws_connect
from websockets.exceptions import InvalidStatus

from bridge_server.http.metrics import PREFIX
from rosbridge_core.protocol.ops import RECEIVED_HEADER, SESSION_HEADER
from tests.bridge.support import wait_subscribers
from tests.helpers import WireClient, async_wait_until
from tests.ops.support import scrape, status

SENT = 5  # the frames the bridge writes in the session before its link drops

BAD_COUNTS: list[tuple[str | None, str]] = [
    ("-5", "is not a count of frames"),
    ("abc", "is not a count of frames"),
    ("", "is empty"),
    ("\u00b2", "is not a count of frames"),  # '²' (ISO-8859-1 on the wire): isdigit() is true
    ("5.0", "is not a count of frames"),
    ("+3", "is not a count of frames"),
    ("0x5", "is not a count of frames"),
    (str(SENT + 1), f"is more than this session has sent ({SENT} frames)"),
    ("99999999999999999999", f"is more than this session has sent ({SENT} frames)"),
    ("9" * 5000, f"is more than this session has sent ({SENT} frames)"),
    (None, "is missing"),
]


async def test_bad_received_counts_are_refused_and_the_session_stays_resumable(
    make_bridge: Any, ros_node: Any, topic: str
) -> None:
    """Each bad X-Rosbridge-Received value gets 400 with one line naming the header and what
    is wrong (logged once, the token never); the kept session is untouched, and a resume with
    a correct count then gets back exactly the frames after that count."""
    bridge = make_bridge("--session-keep", "60")
    ros_pub = ros_node.create_publisher(Int32, topic, 10)
    ws = await ws_connect(bridge.url, additional_headers={SESSION_HEADER: "new"})
    assert ws.response is not None
    token = ws.response.headers[SESSION_HEADER]
    wire = WireClient(ws)
    await wire.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/Int32"})
    await wait_subscribers(ros_pub)
    for i in range(SENT):
        ros_pub.publish(Int32(data=i))
    got = [(await wire.expect(op="publish"))["msg"]["data"] for _ in range(SENT)]
    assert got == list(range(SENT))
    assert all(op["op"] == "session_ack" for op in wire.backlog)  # not counted, not kept
    ws.transport.abort()

    async def parked() -> bool:
        return any(c["parked"] for c in (await status(bridge.port))["clients"])

    async with asyncio.timeout(10):
        while not await parked():
            await asyncio.sleep(0.05)

    for count, problem in BAD_COUNTS:
        headers = {SESSION_HEADER: token}
        if count is not None:
            headers[RECEIVED_HEADER] = count
        with pytest.raises(InvalidStatus) as caught:
            await ws_connect(bridge.url, additional_headers=headers, open_timeout=10)
        response = caught.value.response
        body = response.body.decode()
        assert response.status_code == 400, (count, body)
        assert body.startswith(RECEIVED_HEADER + " ") and problem in body, (count, body)
        assert body.count("\n") == 1 and len(body) < 200, body
        assert await parked()  # the session was not touched

    await async_wait_until(
        lambda: sum("refused a session resume" in line for line in bridge.lines)
        == len(BAD_COUNTS), 10, "one log line per refusal")
    assert not any(token in line for line in bridge.lines)
    assert (await scrape(bridge.port))[PREFIX + "connections_refused_total"] == [
        ({"reason": "http_400"}, len(BAD_COUNTS))]

    again = await ws_connect(bridge.url, additional_headers={
        SESSION_HEADER: token, RECEIVED_HEADER: str(SENT - 2)})
    assert again.response is not None
    assert again.response.headers[SESSION_HEADER] == token
    assert again.response.headers[RECEIVED_HEADER] == "1"  # the subscribe
    wire = WireClient(again)
    ros_pub.publish(Int32(data=SENT))
    got = [(await wire.expect(op="publish"))["msg"]["data"] for _ in range(3)]
    assert got == [SENT - 2, SENT - 1, SENT]  # what it said it missed, then on as before
    assert (await scrape(bridge.port))[PREFIX + "sessions_resumed_total"][0][1] == 1
    await again.close()
