"""The MCP server in process over MockRos, driven by the mcp SDK's own client: schemas from
the robot's definitions, bounds, summaries and timeouts, with no bridge."""

from __future__ import annotations

import asyncio
import json
import subprocess
import sys
from typing import Any, Literal

import jsonschema
import mcp_types as types
import numpy as np
import pytest
from mcp import Client, MCPError

from roslibpy_lite import MockRos
from roslibpy_lite.mcp import Options, build_server
from tests.helpers import ROOT, ros_env
from tests.mcp.support import text


async def test_a_typed_schema_carries_ranges_bounds_and_constants() -> None:
    """publish__<topic>'s schema is the type's definition: integer ranges, fixed and bounded
    arrays, bounded strings and constants; jsonschema accepts a fitting message and names
    the field of one that does not, as the server does."""
    ros = MockRos()
    await ros.advertise("/bounded", "test_msgs/msg/BoundedSequences")
    await ros.advertise("/consts", "test_msgs/msg/Constants")
    async with Client(build_server(ros)) as client:
        tools = {t.name: t for t in (await client.list_tools()).tools}
        schema = tools["publish__bounded"].input_schema
        message = schema["properties"]["message"]["properties"]
        assert message["int8_values"]["items"] == {"type": "integer", "minimum": -128,
                                                   "maximum": 127}
        assert message["int8_values"]["maxItems"] == 3
        assert message["uint8_values"]["anyOf"][0]["contentEncoding"] == "base64"
        consts = tools["publish__consts"].input_schema["properties"]["message"]
        assert consts["x-ros-constants"]["UINT8_CONST"] == 200
        validator = jsonschema.Draft202012Validator(schema)
        assert not list(validator.iter_errors({"message": {"int8_values": [1, -2]}}))
        bad = {"message": {"int8_values": [1, 2, 3, 4]}}
        assert [list(e.absolute_path) for e in validator.iter_errors(bad)] == [
            ["message", "int8_values"]]
        result = await client.call_tool("publish__bounded", bad)
        assert result.is_error and "int8_values" in text(result)
        result = await client.call_tool("publish__bounded", {"message": {"int8_values": [300]}})
        assert result.is_error and "int8_values" in text(result) and "300" in text(result)
    assert ros.published("/bounded") == []


async def test_a_nested_type_is_defined_once_and_referenced() -> None:
    """Nested message types are $defs at the tool schema's root, so $ref resolves."""
    ros = MockRos()
    await ros.advertise("/pose", "geometry_msgs/msg/PoseStamped")
    async with Client(build_server(ros)) as client:
        (tool,) = [t for t in (await client.list_tools()).tools if t.name == "publish__pose"]
        schema = tool.input_schema
        assert set(schema["$defs"]) >= {"geometry_msgs.msg.Pose", "std_msgs.msg.Header",
                                        "builtin_interfaces.msg.Time"}
        validator = jsonschema.Draft202012Validator(schema)
        bad = {"message": {"pose": {"position": {"x": "far"}}}}
        assert [list(e.absolute_path) for e in validator.iter_errors(bad)] == [
            ["message", "pose", "position", "x"]]
        good = {"message": {"header": {"frame_id": "map"}, "pose": {"position": {"x": 1.5}}}}
        assert not list(validator.iter_errors(good))
        assert not (await client.call_tool("publish__pose", good)).is_error
    assert ros.published("/pose")[0]["pose"]["position"]["x"] == 1.5


async def test_a_long_array_is_summarized_and_a_silent_topic_times_out() -> None:
    """read_topic summarizes a 10 000-element array (its count, first items and range) and
    a topic with no message gives a tool error after the caller's timeout."""
    ros = MockRos()
    pub = await ros.advertise("/big", "std_msgs/msg/Float64MultiArray")
    await ros.advertise("/quiet", "std_msgs/msg/String")
    async with Client(build_server(ros, Options(max_text=2000))) as client:
        reading = asyncio.create_task(client.call_tool("read_topic", {"topic": "/big"}))
        while not ros.subscribers("/big"):  # the read has subscribed
            await asyncio.sleep(0)
        await pub.publish({"layout": {"dim": [], "data_offset": 0},
                           "data": [float(i) for i in range(10_000)]})
        result = await reading
        assert not result.is_error, text(result)
        data = json.loads(text(result))["message"]["data"]
        assert data.startswith("<10000 items; first 8: [0.0, 1.0") and "max 9999.0" in data
        result = await client.call_tool("read_topic", {"topic": "/quiet", "timeout": 0.2})
        assert result.is_error and "timeout" in text(result)




async def test_collect_is_bounded_by_count_bytes_and_time_and_reports_progress() -> None:
    """collect_topic stops at max_messages (reporting progress per message), at max_bytes,
    and at its seconds on a quiet topic."""
    ros = MockRos()
    pub = await ros.advertise("/chatter", "std_msgs/msg/String")
    reports: list[tuple[float, float | None]] = []

    async def on_progress(progress: float, total: float | None, message: str | None) -> None:
        reports.append((progress, total))

    async with Client(build_server(ros)) as client:
        async def collect(**bounds: Any) -> dict[str, Any]:
            call = asyncio.create_task(client.call_tool(
                "collect_topic", {"topic": "/chatter", "seconds": 30, **bounds},
                progress_callback=on_progress))
            while not ros.subscribers("/chatter"):  # the collection has subscribed
                await asyncio.sleep(0)
            for i in range(5):
                await pub.publish({"data": f"m{i}" * 20})
            result = await call
            assert not result.is_error, text(result)
            return dict(json.loads(text(result)))

        by_count = await collect(max_messages=3)
        assert (by_count["count"], by_count["stopped_by"]) == (3, "max_messages")
        # in order, from the burst (a burst longer than max_messages keeps its newest)
        data = [m["message"]["data"] for m in by_count["messages"]]
        assert data == sorted(data) and set(data) <= {f"m{i}" * 20 for i in range(5)}
        assert reports == [(1.0, 3.0), (2.0, 3.0), (3.0, 3.0)]
        by_bytes = await collect(max_bytes=160)  # two entries of 75-79 bytes (their "t")
        assert (by_bytes["count"], by_bytes["stopped_by"]) == (2, "max_bytes")
        quiet = await client.call_tool("collect_topic", {"topic": "/chatter", "seconds": 0.2})
        assert json.loads(text(quiet))["stopped_by"] == "seconds"


async def _scaling_robot() -> tuple[MockRos, list[float]]:
    """A MockRos serving /scale (mult_msgs/srv/MultFloats); the x of each request it got."""
    ros = MockRos()
    calls: list[float] = []

    def scale(req: dict[str, Any]) -> dict[str, Any]:
        calls.append(req["x"])
        return {"result": req["x"] * req["y"]}

    await ros.advertise_service("/scale", "mult_msgs/srv/MultFloats", scale)
    return ros, calls


@pytest.mark.parametrize("mode", ["auto", "legacy"])
async def test_confirm_asks_the_user_before_a_change_and_a_no_sends_nothing(mode: str) -> None:
    """With confirm on, a service call is made only once the client's user accepts (MCP
    elicitation naming the tool and its arguments; in the call's answer on 2026-07-28, as a
    request to the client on the handshake era); declined, or a client that cannot answer,
    nothing reaches the service; reading tools are not asked about."""
    ros, calls = await _scaling_robot()
    asked: list[str] = []
    answers: list[Literal["accept", "decline"]] = ["accept", "decline"]

    async def user(context: Any, params: Any) -> types.ElicitResult:
        asked.append(params.message)
        action = answers.pop(0)
        return types.ElicitResult(action=action, content={"confirm": True}
                                  if action == "accept" else None)

    server = build_server(ros, Options(confirm=True))
    request = {"request": {"x": 2.0, "y": 4.0}}
    async with Client(server, elicitation_callback=user, mode=mode) as client:
        assert not (await client.call_tool("list_topics", {})).is_error
        assert asked == []
        result = await client.call_tool("call__scale", request)
        assert not result.is_error and '"result": 8.0' in text(result)
        assert asked == ['Allow call__scale with {"request": {"x": 2.0, "y": 4.0}}?']
        result = await client.call_tool("call__scale", request)
        assert result.is_error and "not confirmed by the user; nothing was sent" in text(result)
    async with Client(server, mode=mode) as client:  # no elicitation callback
        try:  # the SDK's client refuses the question itself on 2026-07-28
            result = await client.call_tool("call__scale", request)
        except MCPError as exc:
            assert "Elicitation not supported" in str(exc)
        else:
            assert result.is_error and "could not be asked" in text(result)
    assert calls == [2.0]


@pytest.mark.parametrize("mode", ["auto", "legacy"])
@pytest.mark.parametrize("state", [None, "forged"])
async def test_a_confirmation_sent_before_it_is_asked_confirms_nothing(
    mode: str, state: str | None
) -> None:
    """A client that sends input_responses.confirm = accept on its first call (with no request
    state, or one the server never issued) does not skip --confirm: the user is asked, and
    with no one to answer nothing reaches the service."""
    ros, calls = await _scaling_robot()
    accept = types.ElicitResult(action="accept", content={"confirm": True})
    async with Client(build_server(ros, Options(confirm=True)), mode=mode) as client:
        try:
            result = await client.call_tool("call__scale", {"request": {"x": 2.0, "y": 4.0}},
                                            input_responses={"confirm": accept},
                                            request_state=state)
        except MCPError as exc:  # the SDK's client cannot answer the real question
            assert "Elicitation not supported" in str(exc) or "requestState" in str(exc), exc
        else:
            assert result.is_error, text(result)
    assert calls == []


async def test_a_confirmation_answers_its_one_question_once() -> None:
    """The user's answer to the question the server asked (with its sealed request state)
    makes the change once: the state with other arguments is refused, and sent again it asks
    anew and sends nothing."""
    ros, calls = await _scaling_robot()
    accept: types.InputResponses = {
        "confirm": types.ElicitResult(action="accept", content={"confirm": True})}
    request = {"request": {"x": 2.0, "y": 4.0}}
    async with Client(build_server(ros, Options(confirm=True))) as client:
        session = client.session
        asked = await session.call_tool("call__scale", request, allow_input_required=True)
        assert isinstance(asked, types.InputRequiredResult) and asked.request_state
        with pytest.raises(MCPError, match="requestState"):
            await session.call_tool("call__scale", {"request": {"x": 9.0, "y": 4.0}},
                                    input_responses=accept, request_state=asked.request_state,
                                    allow_input_required=True)
        done = await session.call_tool("call__scale", request, input_responses=accept,
                                       request_state=asked.request_state,
                                       allow_input_required=True)
        assert isinstance(done, types.CallToolResult) and not done.is_error, done
        again = await session.call_tool("call__scale", request, input_responses=accept,
                                        request_state=asked.request_state,
                                        allow_input_required=True)
        assert isinstance(again, types.InputRequiredResult), again
    assert calls == [2.0]


async def test_a_point_cloud_is_summarized_by_its_numbers() -> None:
    """read_topic on a PointCloud2 gives its point count and each field's finite range and
    mean (a NaN point left out), not its bytes."""
    ros = MockRos()
    pub = await ros.advertise("/cloud", "sensor_msgs/msg/PointCloud2")
    xyz = np.array([[0.0, 1.0, 2.0], [4.0, -1.0, 2.0], [np.nan, 0.0, 2.0]] + [[2.0, 0.0, 2.0]] * 5,
                   np.float32)
    fields = [{"name": n, "offset": 4 * i, "datatype": 7, "count": 1}
              for i, n in enumerate("xyz")]
    cloud = {"header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": "lidar"},
             "height": 1, "width": 8, "fields": fields, "is_bigendian": False,
             "point_step": 12, "row_step": 96, "data": list(xyz.tobytes()), "is_dense": False}
    async with Client(build_server(ros)) as client:
        reading = asyncio.create_task(client.call_tool("read_topic", {"topic": "/cloud"}))
        while not ros.subscribers("/cloud"):  # the read has subscribed
            await asyncio.sleep(0)
        await pub.publish(cloud)
        result = await reading
        assert not result.is_error, text(result)
        message = json.loads(text(result))["message"]
        assert message["data"] == "<96 bytes>"
        assert message["points"] == {"count": 8, "fields": {
            "x": {"min": 0.0, "max": 4.0, "mean": 2.0},
            "y": {"min": -1.0, "max": 1.0, "mean": 0.0},
            "z": {"min": 2.0, "max": 2.0, "mean": 2.0}}}


def test_without_the_extra_the_client_imports_and_mcp_says_what_to_install() -> None:
    """With the mcp SDK absent, roslibpy_lite and its CLI import, and 'roslibpy-lite mcp'
    exits with a usage error naming the mcp extra."""
    code = ("import sys; sys.modules['mcp'] = None\n"
            "import roslibpy_lite, roslibpy_lite.cli\n"
            "sys.exit(roslibpy_lite.cli.main(['mcp', '--url', 'ws://127.0.0.1:9']))")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                          text=True, timeout=60, env=ros_env(PYTHONPATH=str(ROOT)))
    assert done.returncode == 2, done.stderr
    assert "install roslibpy-lite with its mcp extra" in done.stderr


async def test_a_missing_parameter_is_an_error_naming_it() -> None:
    """get_param of a parameter the node does not have is a tool error naming it (not a
    null value); one it has gives its value."""
    ros = MockRos()
    ros.add_node("/camera", {"gain": 2.5})
    async with Client(build_server(ros)) as client:
        result = await client.call_tool("get_param", {"name": "/camera:gain"})
        assert not result.is_error and text(result) == "2.5", text(result)
        result = await client.call_tool("get_param", {"name": "/camera:exposure"})
        assert result.is_error and "no parameter /camera:exposure" in text(result)
