"""Limits: origins, clients in all and per address, handshake timeout, op rate, caps, byte budget.

Each limit answers the offender clearly and leaves the other clients alone.
"""

from __future__ import annotations

import asyncio
from typing import Any

import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.frames import Frame, Opcode
from websockets.typing import Origin

from bridge_server.front.websocket import BudgetAssembler, Inbound
from tests.bridge.action_support import FibServer, send_goal
from tests.helpers import open_wire, roundtrip


async def _refused(url: str, **kwargs: Any) -> tuple[int, str]:
    with pytest.raises(InvalidStatus) as info:
        await connect(url, open_timeout=10, **kwargs)
    response = info.value.response
    return response.status_code, bytes(response.body or b"").decode()


async def test_allowed_origins(make_bridge: Any) -> None:
    """A browser from an origin not listed is refused (403); listed origins and non-browsers pass."""
    bridge = make_bridge("--allowed-origins", "https://ui.example.com, http://localhost:8080")
    code, text = await _refused(bridge.url, origin="https://evil.example")
    assert code == 403 and "https://evil.example" in text and "not allowed" in text
    for origin in (Origin("https://ui.example.com"), None):
        ws = await connect(bridge.url, origin=origin, open_timeout=10)
        await ws.close()


async def test_max_clients(make_bridge: Any) -> None:
    """Past --max-clients a new client gets 503 naming the limit; a freed place can be taken."""
    bridge = make_bridge("--max-clients", "2")
    first, second = await open_wire(bridge.url), await open_wire(bridge.url)
    code, text = await _refused(bridge.url)
    assert code == 503 and "at most 2" in text
    await roundtrip(first)  # the others are untouched
    start = len(bridge.lines)
    await second.close()
    bridge.wait_for_line("disconnected", start=start)
    third = await open_wire(bridge.url)
    await roundtrip(third)
    await first.close()
    await third.close()


async def test_max_clients_per_address(make_bridge: Any) -> None:
    """Past --max-clients-per-address a second client from 127.0.0.1 gets 429."""
    bridge = make_bridge("--max-clients-per-address", "1")
    first = await open_wire(bridge.url)
    code, text = await _refused(bridge.url)
    assert code == 429 and "too many clients from 127.0.0.1" in text
    await roundtrip(first)
    await first.close()


async def test_handshake_timeout_closes_a_silent_socket(make_bridge: Any) -> None:
    """A TCP connection that never sends a handshake is closed after --handshake-timeout."""
    bridge = make_bridge("--handshake-timeout", "1")
    reader, writer = await asyncio.open_connection("127.0.0.1", bridge.port)
    try:
        assert await asyncio.wait_for(reader.read(), 30) == b""
    finally:
        writer.close()
    ws = await open_wire(bridge.url)  # the bridge serves others as before
    await roundtrip(ws)
    await ws.close()


async def test_op_rate_warns_then_closes(make_bridge: Any) -> None:
    """Over --max-op-rate a client gets a warning status, then a close 1008; others go on."""
    bridge = make_bridge("--max-op-rate", "20", "--op-burst", "20")
    other = await open_wire(bridge.url)
    flooder = await open_wire(bridge.url)
    for i in range(100):
        await flooder.send({"op": "set_level", "level": "warning", "id": i})
    warning = await flooder.expect(op="status", level="warning")
    assert "op rate limit" in warning["msg"] and "20" in warning["msg"]
    with pytest.raises(ConnectionClosed) as info:
        while True:
            await flooder.recv()
    assert info.value.rcvd is not None and info.value.rcvd.code == 1008
    assert "too many ops" in info.value.rcvd.reason
    await roundtrip(other)
    await other.close()


async def test_caps_on_subscriptions_publishers_and_services(make_bridge: Any, topic: str) -> None:
    """Past each per-client cap the op fails with a status naming the cap; existing names still work."""
    bridge = make_bridge("--max-subscriptions", "1", "--max-publishers", "1",
                         "--max-services", "1")
    ws = await open_wire(bridge.url)
    string, setbool = "std_msgs/msg/String", "std_srvs/srv/SetBool"
    await ws.send({"op": "subscribe", "topic": topic + "_a", "type": string, "id": "s1"})
    await ws.send({"op": "subscribe", "topic": topic + "_a", "type": string, "id": "s2"})
    await ws.send({"op": "subscribe", "topic": topic + "_b", "type": string, "id": "s3"})
    assert "too many subscriptions" in (await ws.expect(op="status", id="s3"))["msg"]
    await ws.send({"op": "advertise", "topic": topic + "_a", "type": string, "id": "a1"})
    await ws.send({"op": "advertise", "topic": topic + "_b", "type": string, "id": "a2"})
    assert "too many publishers" in (await ws.expect(op="status", id="a2"))["msg"]
    await ws.send({"op": "advertise_service", "service": topic + "_a", "type": setbool})
    await ws.send({"op": "advertise_service", "service": topic + "_b", "type": setbool,
                   "id": "v2"})
    assert "too many served services" in (await ws.expect(op="status", id="v2"))["msg"]
    fib = "test_msgs/action/Fibonacci"
    await ws.send({"op": "advertise_action", "action": topic + "_a", "type": fib, "id": "x1"})
    await ws.send({"op": "advertise_action", "action": topic + "_b", "type": fib, "id": "x2"})
    assert "too many served actions" in (await ws.expect(op="status", id="x2"))["msg"]
    await roundtrip(ws)
    assert not [op for op in ws.backlog if op.get("id") in ("s1", "s2", "a1", "x1")]
    await ws.close()


async def test_inbound_byte_budget_pauses_and_resumes_reading() -> None:
    """Frames waiting past the connection's byte budget (or the total) pause reading until read."""
    calls: list[str] = []
    totals = Inbound()
    asm = BudgetAssembler(1000, 1500, totals, high=64, low=16,
                           pause=lambda: calls.append("pause"),
                           resume=lambda: calls.append("resume"))
    other = BudgetAssembler(1000, 1500, totals, high=64, low=16,
                             pause=lambda: calls.append("other pause"), resume=lambda: None)
    asm.put(Frame(Opcode.TEXT, b"x" * 600))
    assert calls == [] and totals.bytes == 600
    asm.put(Frame(Opcode.TEXT, b"x" * 600))
    assert calls == ["pause"]
    other.put(Frame(Opcode.TEXT, b"y" * 400))  # 1600 in all: over the total budget
    assert calls == ["pause", "other pause"]
    assert await asm.get() == "x" * 600
    assert calls[-1] != "resume"  # still 600 bytes waiting: more than a quarter of the budget
    assert await asm.get() == "x" * 600
    assert calls[-1] == "resume" and totals.bytes == 400


async def test_websockets_internals_are_checked_at_start_up(monkeypatch: pytest.MonkeyPatch) -> None:
    """The budget's websockets internals pass the start-up check; if they change, it says so."""
    from bridge_server.front.websocket import check_websockets_internals
    from bridge_server.rclpy_graph.types import BridgeError

    check_websockets_internals()
    monkeypatch.setattr(BudgetAssembler, "maybe_pause", lambda self: None)
    with pytest.raises(BridgeError, match=r"websockets \S+ is not supported by the bridge"):
        check_websockets_internals()


async def test_the_frame_boundary_websockets_parser_waits_at_is_checked_at_start_up(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """If websockets' parser no longer waited in StreamReader.at_eof between frames (where the
    bridge looks before reading frames itself), the start-up check says so."""
    from websockets.streams import StreamReader

    from bridge_server.front.websocket import check_websockets_internals
    from bridge_server.rclpy_graph.types import BridgeError

    def at_eof(self: StreamReader) -> Any:
        while not self.buffer and not self.eof:
            yield
        return not self.buffer

    monkeypatch.setattr(StreamReader, "at_eof", at_eof)
    with pytest.raises(BridgeError, match=r"does not wait in StreamReader\.at_eof"):
        check_websockets_internals()


def test_rclpy_internals_are_checked_at_start_up(monkeypatch: pytest.MonkeyPatch) -> None:
    """The action code's rclpy internals pass the start-up check; if one is gone, it says so."""
    from rclpy.action.server import ServerGoalHandle

    from bridge_server.rclpy_graph.actions import check_rclpy_internals
    from bridge_server.rclpy_graph.types import BridgeError

    check_rclpy_internals()
    monkeypatch.delattr(ServerGoalHandle, "_update_state")
    with pytest.raises(BridgeError, match=r"ServerGoalHandle\._update_state"):
        check_rclpy_internals()


async def test_cap_on_goals_in_flight(make_bridge: Any, ros_node: Any, topic: str) -> None:
    """Past --max-goals a goal fails with a status naming the cap; a finished goal frees its place."""
    bridge = make_bridge("--max-goals", "1")
    server = FibServer(ros_node, topic, slow=True)
    ws = await open_wire(bridge.url)
    await send_goal(ws, topic, {"order": 2}, "g1", feedback=True)
    await ws.expect(op="action_feedback", id="g1")  # accepted and running
    await send_goal(ws, topic, {"order": 2}, "g2")
    assert "too many goals in flight on this connection (at most 1)" in (
        await ws.expect(op="status", id="g2"))["msg"]
    refused = await ws.expect(op="action_result", id="g2")
    assert (refused["result"], refused["status"]) == (False, 6)
    await ws.send({"op": "cancel_action_goal", "id": "g1", "action": topic})
    assert (await ws.expect(op="action_result", id="g1"))["status"] == 5  # CANCELED
    await send_goal(ws, topic, {"order": 2}, "g3", feedback=True)
    await ws.expect(op="action_feedback", id="g3")
    await ws.send({"op": "cancel_action_goal", "id": "g3", "action": topic})
    assert (await ws.expect(op="action_result", id="g3"))["status"] == 5
    await ws.close()
    server.destroy()
