"""The MCP server in process over MockRos, driven by the mcp SDK's own client: schemas from
the robot's definitions, bounds, summaries and timeouts, with no bridge."""

from __future__ import annotations

import asyncio
import json
from typing import Any

import jsonschema
from mcp import Client

from roslibpy_lite import MockRos
from roslibpy_lite.mcp import Options, build_server
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
        by_bytes = await collect(max_bytes=150)
        assert (by_bytes["count"], by_bytes["stopped_by"]) == (2, "max_bytes")
        quiet = await client.call_tool("collect_topic", {"topic": "/chatter", "seconds": 0.2})
        assert json.loads(text(quiet))["stopped_by"] == "seconds"
