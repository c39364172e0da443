"""Fragments against a real bridge: a piece sent twice is refused, and what a connection's
incomplete fragmented ops hold stays within --max-message-size however the pieces come."""

from __future__ import annotations

from collections.abc import Iterator

import psutil
import pytest

from tests.helpers import BridgeProcess, roundtrip
from tests.security.support import AuthFile, wire

LIMIT = 1 << 20
"""The bridge's --max-message-size here: the largest frame, and what fragments may hold."""

BIG = 900_000
"""The data of a large piece (a frame just under LIMIT)."""


@pytest.fixture(scope="module")
def small_bridge(auth: AuthFile) -> Iterator[BridgeProcess]:
    """A bridge requiring tokens, with --max-message-size 1 MiB."""
    proc = BridgeProcess(args=["--auth-file", str(auth.path),
                               "--max-message-size", str(LIMIT)]).start()
    yield proc
    proc.stop()


def _rss(bridge: BridgeProcess) -> int:
    assert bridge.proc is not None
    return int(psutil.Process(bridge.proc.pid).memory_info().rss)


async def test_pieces_sent_again_larger_are_refused_and_memory_stays_bounded(
    small_bridge: BridgeProcess, auth: AuthFile
) -> None:
    """Issue 39's attack (each piece number sent small, then again nearly a frame large) by a
    subscribe-only client: each repeat gets a status error naming the id and the piece, the
    bridge's RSS grows by far less than what was sent, and the connection and another
    client go on working."""
    attacker = await wire(small_bridge.url, auth.tokens["viewer"])
    other = await wire(small_bridge.url, auth.tokens["viewer"])
    await roundtrip(attacker)
    await roundtrip(other)
    before = _rss(small_bridge)
    rounds = 100
    for num in range(rounds):
        await attacker.send({"op": "fragment", "id": "f", "data": "x", "num": num,
                             "total": 1000})
        await attacker.send({"op": "fragment", "id": "f", "data": "y" * BIG, "num": num,
                             "total": 1000})
    await roundtrip(attacker)
    grown = _rss(small_bridge) - before
    print(f"bridge RSS before {before >> 20} MiB, after {rounds} repeated pieces of "
          f"{BIG} bytes: +{grown / 2**20:.1f} MiB")
    assert grown < 20 * 2**20, f"the bridge grew by {grown >> 20} MiB"
    errors = [op for op in attacker.backlog if op.get("op") == "status"
              and op.get("level") == "error"]
    assert [e["msg"] for e in errors] == [
        f"fragment 'f': piece {num} of 1000 was sent twice" for num in range(rounds)]
    assert all(e["id"] == "f" for e in errors)
    await roundtrip(other)
    await attacker.send({"op": "fragment", "id": "g", "data": '{"op": "call_service", ',
                         "num": 0, "total": 2})
    await attacker.send({"op": "fragment", "id": "g", "num": 1, "total": 2,
                         "data": '"service": "/rosapi/get_ros_version", "id": "whole"}'})
    await attacker.expect(op="service_response", id="whole")  # fragments still work
    await attacker.close()
    await other.close()


async def test_pieces_past_the_bound_are_refused_whatever_their_ids(
    small_bridge: BridgeProcess, auth: AuthFile
) -> None:
    """Large pieces of different numbers, under two ids, are refused once together they would
    pass --max-message-size: a status error naming the id, the piece and the bound."""
    client = await wire(small_bridge.url, auth.tokens["viewer"])
    await client.send({"op": "fragment", "id": "a", "data": "y" * BIG, "num": 0, "total": 9})
    await client.send({"op": "fragment", "id": "b", "data": "y" * BIG, "num": 0, "total": 9})
    error = await client.expect(op="status", level="error")
    assert error["id"] == "b"
    assert error["msg"] == (f"fragment 'b': piece 0 would take the fragments held for this "
                            f"connection past {LIMIT} bytes")
    await roundtrip(client)
    await client.close()
