"""The holes hostile-input probes found, each closed: bad names, lone surrogates, lost fragments."""

from __future__ import annotations

import json
from typing import Any

import pytest

from rosbridge_core.security.names import InvalidNameError, check_name
from tests.helpers import BridgeProcess, roundtrip


def _with_surrogate(op: dict[str, Any]) -> str:
    """The op's JSON text with the string "S" replaced by a lone surrogate escape (\\ud800)."""
    return json.dumps(op).replace('"S"', '"\\ud800"')


BAD_NAMES = ["/foo bar", "//x", "/1abc", "/a/", "/caf\u00e9", "/x\ud800"]


@pytest.mark.parametrize("name", BAD_NAMES)
def test_check_name_refuses_invalid_names(name: str) -> None:
    """Each invalid name is refused with a message quoting it."""
    with pytest.raises(InvalidNameError, match="invalid topic name"):
        check_name(name)


def test_check_name_accepts_valid_names() -> None:
    """Ordinary names (nested, underscores, digits after the first character) pass."""
    for name in ("/a", "/robot_1/cmd_vel", "/_private/x2", "/rosapi/topics"):
        check_name(name)


@pytest.mark.parametrize("name", ["/foo bar", "//x", "/1abc", "/a/"])
async def test_subscribe_without_type_to_an_invalid_name_is_refused(ws_connect: Any, name: str) -> None:
    """A subscribe without a type to an invalid name gets a status error naming it."""
    ws = await ws_connect()
    await ws.send({"op": "subscribe", "topic": name, "id": "s"})
    status = await ws.expect(op="status", id="s")
    assert status["level"] == "error" and "invalid topic name" in status["msg"]
    assert repr(name) in status["msg"]


async def _no_traceback_since(bridge: BridgeProcess, start: int, ws: Any) -> list[str]:
    await roundtrip(ws)
    lines = bridge.lines[start:]
    assert not [line for line in lines if "Traceback" in line or " ERROR " in line], lines
    return lines


@pytest.mark.parametrize(
    ("op", "field"),
    [("advertise", "topic"), ("advertise_service", "service"), ("publish", "topic"),
     ("call_service", "service")],
)
async def test_invalid_names_are_one_clean_error(
    ws_connect: Any, bridge: BridgeProcess, op: str, field: str
) -> None:
    """Invalid names on any op give a status naming the problem and no traceback in the log."""
    ws = await ws_connect()
    start = len(bridge.lines)
    body: dict[str, Any] = {"op": op, field: "/bad name", "id": "x"}
    extra: dict[str, dict[str, Any]] = {"advertise": {"type": "std_msgs/msg/String"},
                                        "advertise_service": {"type": "std_srvs/srv/SetBool"},
                                        "publish": {"msg": {}}, "call_service": {}}
    body.update(extra[op])
    await ws.send(body)
    status = await ws.expect(op="status", id="x")
    assert "invalid" in status["msg"] and "'/bad name'" in status["msg"]
    lines = await _no_traceback_since(bridge, start, ws)
    assert len([line for line in lines if "/bad name" in line]) <= 1


async def test_lone_surrogate_in_a_published_string(
    ws_connect: Any, bridge: BridgeProcess, topic: str
) -> None:
    """A JSON string holding a lone surrogate is refused with a status that says so, no traceback."""
    ws = await ws_connect()
    start = len(bridge.lines)
    await ws.send({"op": "advertise", "topic": topic, "type": "std_msgs/msg/String"})
    await ws.send_raw(_with_surrogate({"op": "publish", "topic": topic, "msg": {"data": "S"},
                                       "id": "p"}))
    status = await ws.expect(op="status", id="p")
    assert status["level"] == "error" and "surrogate" in status["msg"]
    assert "Error" not in status["msg"]  # no exception class names
    await _no_traceback_since(bridge, start, ws)


async def test_lone_surrogate_in_service_call_args(
    ws_connect: Any, bridge: BridgeProcess, ros_node: Any, topic: str
) -> None:
    """A lone surrogate in call_service args fails the call with a clear reason, no traceback."""
    from test_msgs.srv import BasicTypes

    ros_node.create_service(BasicTypes, topic, lambda q, r: r)
    ws = await ws_connect()
    start = len(bridge.lines)
    await ws.send_raw(_with_surrogate({"op": "call_service", "service": topic, "id": "c",
                                       "type": "test_msgs/srv/BasicTypes", "timeout": 30,
                                       "args": {"string_value": "S"}}))
    reply = await ws.expect(op="service_response", id="c")
    assert reply["result"] is False and "surrogate" in reply["values"]
    await _no_traceback_since(bridge, start, ws)


async def test_fragments_dropped_for_room_are_reported(ws_connect: Any) -> None:
    """When more fragmented ops are incomplete than the bridge keeps, the sender hears which."""
    ws = await ws_connect()
    for i in range(17):  # the bridge keeps 16 incomplete fragmented ops per connection
        await ws.send({"op": "fragment", "id": f"f{i}", "data": "{", "num": 0, "total": 2})
    status = await ws.expect(op="status", id="f0")
    assert status["level"] == "error"
    assert "dropped with 1 of 2 pieces" in status["msg"] and "16" in status["msg"]


@pytest.mark.parametrize("name", ["/bad node:x", "/n\ud800:x", "//n:x"])
async def test_invalid_node_in_a_parameter_name(ws_connect: Any, bridge: BridgeProcess, name: str) -> None:
    """A bad node in a rosapi parameter name fails the call naming it, with no traceback."""
    ws = await ws_connect()
    start = len(bridge.lines)
    await ws.send_raw(json.dumps({"op": "call_service", "service": "/rosapi/get_param",
                                  "args": {"name": name}, "id": "p"}))
    reply = await ws.expect(op="service_response", id="p")
    assert reply["result"] is False and "invalid node name" in reply["values"]
    await _no_traceback_since(bridge, start, ws)


@pytest.mark.parametrize(
    ("service", "args", "expected"),
    [
        ("publishers", {"topic": "/bad name"}, "invalid topic name"),
        ("subscribers", {"topic": "//x"}, "invalid topic name"),
        ("subscribers", {"topic": "\ud800"}, "invalid topic name"),
        ("has_param", {"name": "/no_such_node_here:x"}, "does not answer"),
    ],
)
async def test_rosapi_lookups_with_bad_names(
    ws_connect: Any, bridge: BridgeProcess, service: str, args: dict[str, Any], expected: str
) -> None:
    """rosapi lookups with invalid or unknown names fail with a reason, no traceback."""
    ws = await ws_connect()
    start = len(bridge.lines)
    await ws.send_raw(json.dumps({"op": "call_service", "service": f"/rosapi/{service}",
                                  "args": args, "id": "r"}))
    reply = await ws.expect(op="service_response", id="r")
    assert reply["result"] is False and expected in reply["values"]
    await _no_traceback_since(bridge, start, ws)
