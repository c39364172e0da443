"""The client reads the bridge's answer to a session resume strictly: a received count that
is not ASCII decimal digits, or more than the client sent, ends the client with a clear error
(a real websocket peer plays the bridge's handshake), and the sans-I/O ClientSession refuses
each such value the same way."""

from __future__ import annotations

import asyncio

import pytest

import roslibpy_lite
from rosbridge_core.protocol.ops import RECEIVED_HEADER, SESSION_HEADER
from roslibpy_lite import ConnectionState
from roslibpy_lite.exceptions import RemoteProtocolError
from roslibpy_lite.transports.resumable import ClientSession
from roslibpy_lite.transports.websocket import WebSocketTransport
from tests.client.support import ScriptedPeer, fast_backoff

BAD_COUNTS = [
    ("-1", "is not a count of frames"),
    ("abc", "is not a count of frames"),
    ("\u00b2", "is not a count of frames"),  # '²': str.isdigit() says yes, int() says no
    ("1.0", "is not a count of frames"),
    ("", "is empty"),
    ("3", "is more than this session has sent (2 frames)"),
    ("99999999999999999999", "is more than this session has sent (2 frames)"),
]


@pytest.mark.parametrize(("count", "problem"), BAD_COUNTS)
def test_client_session_refuses_a_bad_count(count: str, problem: str) -> None:
    """A resume answered with a bad count raises RemoteProtocolError naming the header and
    the problem; the session's counts are left as they were."""
    session = ClientSession()
    session.opened({SESSION_HEADER: "tok"})
    session.wrote("a")
    session.wrote("b")
    with pytest.raises(RemoteProtocolError) as caught:
        session.opened({SESSION_HEADER: "tok", RECEIVED_HEADER: count})
    assert RECEIVED_HEADER in str(caught.value) and problem in str(caught.value)
    assert (session.sent, len(session.unconfirmed), session.resumes) == (2, 2, 0)
    assert session.opened({SESSION_HEADER: "tok", RECEIVED_HEADER: "1"}) == (True, ["b"])


@pytest.mark.parametrize(("count", "problem"),
                         [(c, p.replace("(2 frames", "(1 frames")) for c, p in BAD_COUNTS
                          if c != "3"])
async def test_a_bad_count_in_the_resume_answer_ends_the_client(
    count: str, problem: str, caplog: pytest.LogCaptureFixture
) -> None:
    """Over a real websocket: the peer grants a session, drops the link, and answers the
    client's resume with a bad count; the client closes (no resume on a count it cannot
    trust) and logs one error naming the header and the problem."""
    peer = await ScriptedPeer().start()
    peer.answer_headers = {SESSION_HEADER: "tok"}
    try:
        async with roslibpy_lite.connect(peer.url, backoff=fast_backoff()) as ros:
            transport = ros._transport
            assert isinstance(transport, WebSocketTransport)
            assert transport.session is not None
            assert transport.session.token == "tok"
            ros.advertise("/x", "std_msgs/msg/Int32")  # the one frame it sent
            await peer.expect(op="advertise")
            peer.answer_headers = {SESSION_HEADER: "tok", RECEIVED_HEADER: count}
            async with asyncio.timeout(10), ros.state_changes() as changes:
                await peer.drop()
                while ros.state is not ConnectionState.CLOSED:
                    await changes.next()
        errors = [r.getMessage() for r in caplog.records if r.levelname == "ERROR"]
        assert len(errors) == 1, errors
        text = errors[0]
        assert f"{RECEIVED_HEADER} " in text and problem in text, text
        assert "\n" not in text and "tok" not in text
        assert len(peer.conns) == 2  # it tried to resume once, then stopped
    finally:
        await peer.stop()
