"""Caps across connections (issue 53, finding 7), against a real bridge: what all the
connections of one token, and of one address, hold together is bounded, for fragment memory
(the pieces of incomplete ``fragment`` ops) and in-flight bytes (an incomplete websocket frame,
a fragmented websocket message), and the sender over the cap is told which limit it passed."""

from __future__ import annotations

import asyncio
import base64
import os
from collections.abc import Iterator

import psutil
import pytest
from websockets.frames import Frame, Opcode

from rosbridge_core.security.accounts import DEFAULT_MESSAGES
from rosbridge_core.security.options import MAX_MESSAGE_SIZE
from tests.helpers import BridgeProcess, WireClient, async_wait_until, roundtrip
from tests.security.support import AuthFile, wire, write_auth_file

CONNECTIONS = 30
PIECE = 15_900_000
"""What each connection holds: the red team's 15.9 MB fragment (under --max-message-size)."""

DEFAULT_CAP = DEFAULT_MESSAGES * MAX_MESSAGE_SIZE
"""A principal's (and an address's) default limit of each kind."""

GROWTH_BOUND = 300 * 2**20
"""The bridge's RSS may grow by at most this much: the default cap (64 MiB) and what decoding
30 frames of 15.9 MB leaves allocated (+152 MiB measured for fragments), with room to spare;
without the caps 30 connections hold 30 x 15.9 MB (+516 MiB measured)."""


@pytest.fixture(scope="module")
def capped_bridge(auth: AuthFile) -> Iterator[BridgeProcess]:
    """A bridge requiring tokens, with the default limits (no keepalive: the raw websockets
    here answer no ping, and a slow run must not see them dropped for that)."""
    proc = BridgeProcess(args=["--auth-file", str(auth.path), "--keepalive-interval", "0"]
                         ).start()
    yield proc
    proc.stop()


def _rss(bridge: BridgeProcess) -> int:
    assert bridge.proc is not None
    return int(psutil.Process(bridge.proc.pid).memory_info().rss)


def _refused_errors(client: WireClient) -> list[str]:
    return [op["msg"] for op in client.backlog
            if op.get("op") == "status" and op.get("level") == "error"]


async def test_one_tokens_connections_hold_fragments_up_to_the_per_token_limit(
    capped_bridge: BridgeProcess, auth: AuthFile
) -> None:
    """30 connections of one viewer token, from one address, each send the first 15.9 MB
    piece of a fragmented op: as many as fit in the default per-token limit are held, every
    other sender gets a status error naming the per-token limit, the bridge's RSS stays far
    under what 30 pieces take, and the held ops and another client go on working."""
    clients = [await wire(capped_bridge.url, auth.tokens["viewer"]) for _ in range(CONNECTIONS)]
    other = await wire(capped_bridge.url, auth.tokens["tester"])
    for client in (*clients, other):
        await roundtrip(client)
    before = _rss(capped_bridge)
    for client in clients:  # leading whitespace: the op these pieces make is valid JSON
        await client.send({"op": "fragment", "id": "big", "data": " " * PIECE, "num": 0,
                           "total": 2})
        await roundtrip(client)
    grown = _rss(capped_bridge) - before
    print(f"bridge RSS {before / 2**20:.0f} MiB before, +{grown / 2**20:.0f} MiB after "
          f"{CONNECTIONS} connections of one token each sent a {PIECE / 1e6} MB piece")
    held = [c for c in clients if not _refused_errors(c)]
    refused = [c for c in clients if _refused_errors(c)]
    assert len(held) == DEFAULT_CAP // PIECE
    expected = ("fragment 'big': piece 0 refused: fragment memory of principal viewer_user's "
                "connections would pass the per-token limit "
                f"(fragment_bytes {DEFAULT_CAP} bytes)")
    assert all(_refused_errors(c) == [expected] for c in refused)
    assert grown < GROWTH_BOUND, f"the bridge grew by {grown >> 20} MiB"
    await roundtrip(other)
    await held[0].send({"op": "fragment", "id": "big", "num": 1, "total": 2,
                        "data": '{"op": "call_service", "service": "/rosapi/get_ros_version", '
                                '"id": "whole"}'})
    await held[0].expect(op="service_response", id="whole")
    # the completed op gave its bytes back: a refused connection's piece is held now
    await refused[0].send({"op": "fragment", "id": "again", "data": " " * PIECE, "num": 0,
                           "total": 2})
    await roundtrip(refused[0], id="after")
    assert _refused_errors(refused[0]) == [expected]
    for client in (*clients, other):
        await client.close()


async def test_a_connections_last_frame_is_freed_when_it_drops(
    capped_bridge: BridgeProcess, auth: AuthFile
) -> None:
    """Four connections each send a 15.9 MB frame (refused once read: its fragment makes no
    valid op) and drop: once the bridge logged them gone its RSS is back near where it was
    (websockets' parser kept the last frame it read in a reference cycle with the protocol
    until the cyclic collector ran: +91 MiB measured for four)."""
    clients = [await wire(capped_bridge.url, auth.tokens["viewer"])
               for _ in range(DEFAULT_CAP // PIECE)]
    for client in clients:
        await roundtrip(client)
    before = _rss(capped_bridge)
    for client in clients:  # nothing sent after it: it is the last frame the parser read
        await client.send({"op": "fragment", "id": "bad", "data": " " * PIECE, "num": 0,
                           "total": 1})
        await client.expect(op="status", level="error", id="bad")
    start = len(capped_bridge.lines)
    ports = [c.ws.local_address[1] for c in clients]
    for client in clients:
        client.ws.transport.abort()  # gone without a close frame (the parser meets EOF)
    for client in clients:
        await client.ws.wait_closed()  # the socket is closed (on the loop's next turn)
    for port in ports:
        capped_bridge.wait_for_line(rf"\(127\.0\.0\.1:{port}\) disconnected", start=start)
    left = _rss(capped_bridge) - before
    print(f"bridge RSS +{left / 2**20:.0f} MiB once {len(clients)} connections that each "
          f"sent a {PIECE / 1e6} MB frame dropped")
    assert left < PIECE // 2, f"{left >> 20} MiB still held after the connections left"


# -- in-flight bytes: raw websocket frames ----------------------------------------------------


async def _raw_websocket(port: int, token: str) -> tuple[asyncio.StreamReader,
                                                         asyncio.StreamWriter]:
    """A websocket opened by hand (so that a test can write half a frame)."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    key = base64.b64encode(os.urandom(16)).decode()
    writer.write((f"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\n"
                  f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                  f"Sec-WebSocket-Version: 13\r\nAuthorization: Bearer {token}\r\n\r\n").encode())
    head = await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), 10)
    assert head.startswith(b"HTTP/1.1 101"), head
    return reader, writer


async def _close_frame(reader: asyncio.StreamReader) -> tuple[int, str]:
    """The code and reason of the close frame the bridge sends (frames before it skipped)."""
    while True:
        head = await reader.readexactly(2)
        size = head[1] & 0x7F
        if size == 126:
            size = int.from_bytes(await reader.readexactly(2))
        elif size == 127:
            size = int.from_bytes(await reader.readexactly(8))
        payload = await reader.readexactly(size)
        if head[0] & 0x0F == Opcode.CLOSE:
            return int.from_bytes(payload[:2]), payload[2:].decode()


def _incomplete(shape: str) -> bytes:
    """Most of a big message, as a client's masked frames: one frame without its last
    1,000 bytes, or a fragmented message without its last frame."""
    if shape == "frame":
        return Frame(Opcode.TEXT, b" " * PIECE).serialize(mask=True)[:-1000]
    half = b" " * (PIECE // 2)
    return (Frame(Opcode.TEXT, half, fin=False).serialize(mask=True)
            + Frame(Opcode.CONT, half, fin=False).serialize(mask=True))


@pytest.mark.parametrize("shape", ["frame", "message"])
async def test_one_tokens_incomplete_messages_are_bounded_by_the_per_token_limit(
    capped_bridge: BridgeProcess, auth: AuthFile, shape: str
) -> None:
    """30 connections of one token each send most of a 15.9 MB websocket message (one frame
    cut short, or a fragmented message without its last frame): the connections that pass
    the per-token limit of in-flight bytes are closed with 1009 and a reason naming that
    limit, the bridge's RSS stays far under what 30 such messages take, and another client
    goes on working."""
    other = await wire(capped_bridge.url, auth.tokens["tester"])
    await roundtrip(other)
    opened = [await _raw_websocket(capped_bridge.port, auth.tokens["viewer"])
              for _ in range(CONNECTIONS)]
    closes = [asyncio.ensure_future(_close_frame(reader)) for reader, _ in opened]
    before = _rss(capped_bridge)
    data = _incomplete(shape)
    for _, writer in opened:
        writer.write(data)
        await writer.drain()
    at_most_held = DEFAULT_CAP // PIECE
    await async_wait_until(lambda: sum(c.done() for c in closes) >= CONNECTIONS - at_most_held,
                           60, "the connections over the per-token limit closed")
    grown = _rss(capped_bridge) - before
    print(f"bridge RSS {before / 2**20:.0f} MiB before, +{grown / 2**20:.0f} MiB after "
          f"{CONNECTIONS} connections of one token each sent most of a {PIECE / 1e6} MB "
          f"{shape}; {sum(c.done() for c in closes)} closed")
    reasons = {c.result() for c in closes if c.done()}
    assert reasons == {(1009, "in-flight bytes of principal viewer_user's connections would "
                              f"pass the per-token limit (inflight_bytes {DEFAULT_CAP} bytes)")}
    assert grown < GROWTH_BOUND, f"the bridge grew by {grown >> 20} MiB"
    await roundtrip(other)
    for close in closes:
        close.cancel()
    for _, writer in opened:
        writer.transport.abort()
    await other.close()


# -- the limits in the auth file --------------------------------------------------------------

SMALL = 2 * 2**20
ADDRESS = 5 * 2**20
PART = 3 * 2**20


@pytest.fixture(scope="module")
def limits_file(tmp_path_factory: pytest.TempPathFactory) -> AuthFile:
    """An auth file with a per-address limit, no default per-principal one, and a role
    with its own (smaller) limit."""
    text = (f"[limits.per_principal]\nfragment_bytes = 0\n\n"
            f"[limits.per_address]\nfragment_bytes = {ADDRESS}\n\n"
            f'[roles.viewer]\nsubscribe = ["*"]\nintrospection = ["*"]\n\n'
            f'[roles.small]\nintrospection = ["*"]\nlimits.fragment_bytes = {SMALL}\n')
    return write_auth_file(tmp_path_factory.mktemp("limits") / "auth.toml", text,
                           [("ann", "viewer"), ("bob", "viewer"), ("cid", "small")])


async def test_limits_come_from_the_auth_files_roles_and_limits_tables(
    limits_file: AuthFile,
) -> None:
    """A role's ``limits.fragment_bytes`` refuses a piece its principal alone would pass
    (per-token; whether the token came in the handshake or an auth op), and ``[limits.per_address]`` a piece two principals from one address would
    pass together (per-address); each error names its limit, and a principal with no
    limit holds what its address allows."""
    bridge = BridgeProcess(args=["--auth-file", str(limits_file.path)]).start()
    try:
        ann, bob, cid = [await wire(bridge.url, limits_file.tokens[n])
                         for n in ("ann", "bob", "cid")]
        by_op = await wire(bridge.url)  # cid again, proving it by an auth op
        await by_op.send({"op": "auth", "mac": limits_file.tokens["cid"]})
        for client in (cid, by_op):
            await client.send({"op": "fragment", "id": "c", "data": " " * PART, "num": 0,
                               "total": 2})
            error = await client.expect(op="status", level="error")
            assert error["msg"] == ("fragment 'c': piece 0 refused: fragment memory of "
                                    "principal cid's connections would pass the per-token "
                                    f"limit (fragment_bytes {SMALL} bytes)")
        await by_op.close()
        await ann.send({"op": "fragment", "id": "a", "data": " " * PART, "num": 0, "total": 2})
        await roundtrip(ann)
        assert not _refused_errors(ann)  # no per-principal limit: the address's applies
        await bob.send({"op": "fragment", "id": "b", "data": " " * PART, "num": 0, "total": 2})
        error = await bob.expect(op="status", level="error")
        assert error["msg"] == ("fragment 'b': piece 0 refused: fragment memory of the "
                                "connections from 127.0.0.1 would pass the per-address limit "
                                f"(fragment_bytes {ADDRESS} bytes)")
        start = len(bridge.lines)
        port = ann.ws.local_address[1]
        await ann.close()  # its pieces go with it
        bridge.wait_for_line(rf"\(127\.0\.0\.1:{port}\) disconnected", start=start)
        await bob.send({"op": "fragment", "id": "b", "data": " " * PART, "num": 0, "total": 2})
        await roundtrip(bob)
        assert not _refused_errors(bob)  # held now: ann's pieces were given back
        await bob.close()
        await cid.close()
    finally:
        bridge.stop()
