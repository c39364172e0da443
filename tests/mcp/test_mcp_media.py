"""Images as images and goals with feedback, result and cancel, through a real bridge with
rclpy nodes, driven by the mcp SDK's own client over stdio."""

from __future__ import annotations

import base64
import io
import json
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image as PILImage
from rclpy.action import ActionServer, CancelResponse  # type: ignore[attr-defined]
from rclpy.callback_groups import ReentrantCallbackGroup
from sensor_msgs.msg import CompressedImage, Image
from test_msgs.action import Fibonacci

from tests.helpers import BridgeProcess, ros_image
from tests.mcp.support import mcp_stdio, text, until_listed, until_tool

PIXELS = np.arange(48 * 64 * 3, dtype=np.uint32).reshape(48, 64, 3).__mod__(251).astype(np.uint8)


def _decoded(result: Any, mime: str = "image/png") -> np.ndarray[Any, Any]:
    (image,) = [b for b in result.content if b.type == "image"]
    assert image.mime_type == mime
    return np.asarray(PILImage.open(io.BytesIO(base64.b64decode(image.data))))


def _png(pixels: np.ndarray[Any, Any]) -> bytes:
    buf = io.BytesIO()
    PILImage.fromarray(pixels).save(buf, format="PNG")
    return buf.getvalue()


async def test_an_image_topic_reads_as_an_image(
    bridge: BridgeProcess, ros_node: Any, topic: str, tmp_path: Path
) -> None:
    """read_topic on an rgb8 and a bgr8 Image gives PNG image content whose pixels are the
    published ones (in RGB), max_size scales it down, and a CompressedImage comes back as a
    JPEG of its pixels."""
    rgb = ros_node.create_publisher(Image, topic + "_rgb", 1)
    bgr = ros_node.create_publisher(Image, topic + "_bgr", 1)
    packed = ros_node.create_publisher(CompressedImage, topic + "_packed", 1)
    columns, rows = np.meshgrid(np.arange(64) * 4, np.arange(48) * 5)
    smooth = np.stack([columns, rows, np.full((48, 64), 90)], axis=-1).astype(np.uint8)
    png = _png(smooth)

    def tick() -> None:
        rgb.publish(ros_image(64, 48, "rgb8", PIXELS.tobytes()))
        bgr.publish(ros_image(64, 48, "bgr8", np.ascontiguousarray(PIXELS[..., ::-1]).tobytes()))
        packed.publish(CompressedImage(format="png", data=png))

    ros_node.create_timer(0.05, tick)
    async with mcp_stdio(bridge.url, None, tmp_path) as client:
        await until_listed(client, "list_topics", topic + "_bgr")
        for name in ("_rgb", "_bgr"):
            result = await client.call_tool("read_topic", {"topic": topic + name,
                                                           "max_size": 64, "timeout": 10})
            assert not result.is_error, text(result)
            assert np.array_equal(_decoded(result), PIXELS), name
            assert "64x48" in text(result)
        result = await client.call_tool("read_topic", {"topic": topic + "_rgb", "max_size": 32,
                                                       "timeout": 10})
        assert _decoded(result).shape == (24, 32, 3)
        result = await client.call_tool("read_topic", {"topic": topic + "_packed",
                                                       "timeout": 10})
        assert not result.is_error, text(result)
        jpeg = _decoded(result, "image/jpeg").astype(int)
        assert jpeg.shape == (48, 64, 3) and np.abs(jpeg - smooth).mean() < 4


def _fibonacci_server(ros_node: Any, name: str) -> threading.Event:
    canceled = threading.Event()

    def execute(goal_handle: Any) -> Any:
        sequence = [0, 1]
        deadline = time.monotonic() + 30
        while len(sequence) <= goal_handle.request.order and time.monotonic() < deadline:
            if goal_handle.is_cancel_requested:
                goal_handle.canceled()
                canceled.set()
                return Fibonacci.Result(sequence=sequence)
            sequence.append((sequence[-1] + sequence[-2]) % 2**31)  # stays an int32
            goal_handle.publish_feedback(Fibonacci.Feedback(sequence=sequence))
            time.sleep(0.02)  # the robot's pace, not the test's synchronisation
        goal_handle.succeed()
        return Fibonacci.Result(sequence=sequence)

    ros_node.mcp_action = ActionServer(  # type: ignore[no-untyped-call]  # kept with the node
        ros_node, Fibonacci, name, execute,
        cancel_callback=lambda _request: CancelResponse.ACCEPT,
        callback_group=ReentrantCallbackGroup())
    return canceled


async def test_a_goal_gives_its_result_and_a_long_one_its_feedback_and_cancels(
    bridge: BridgeProcess, ros_node: Any, topic: str, tmp_path: Path
) -> None:
    """send_goal__<action> returns a short goal's result; a long one comes back running with
    its goal id, follow_goal shows its feedback, cancel_goal reaches the rclpy server and the
    goal ends CANCELED."""
    canceled = _fibonacci_server(ros_node, topic)
    async with mcp_stdio(bridge.url, None, tmp_path) as client:
        tool = await until_tool(client, "send_goal__" + topic.strip("/"))
        order = tool.input_schema["properties"]["goal"]["properties"]["order"]
        assert order["type"] == "integer" and order["maximum"] == 2**31 - 1
        done = json.loads(text(await client.call_tool(tool.name, {"goal": {"order": 5},
                                                                  "timeout": 20})))
        assert done["status"] == "SUCCEEDED", done
        assert done["result"]["sequence"] == [0, 1, 1, 2, 3, 5]
        running = json.loads(text(await client.call_tool(
            tool.name, {"goal": {"order": 100_000}, "timeout": 0.2})))
        assert running["status"] in ("ACCEPTED", "EXECUTING"), running
        goal = {"goal_id": running["goal_id"]}
        deadline = time.monotonic() + 20
        while not running["last_feedback"] and time.monotonic() < deadline:
            running = json.loads(text(await client.call_tool("follow_goal",
                                                             {**goal, "timeout": 0.1})))
        # a list, or its summary once long: either way the first numbers are the robot's
        assert "[0, 1, 1, 2" in json.dumps(running["last_feedback"]["sequence"]), running
        result = await client.call_tool("cancel_goal", goal)
        assert not result.is_error, text(result)
        ended = json.loads(text(await client.call_tool("follow_goal", {**goal, "timeout": 20})))
        assert ended["status"] == "CANCELED", ended
    assert canceled.is_set()
