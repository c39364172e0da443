"""The Notebooks guide runs as a notebook: its cells, top to bottom, in one real Jupyter
kernel, against the bridge and an rclpy node publishing a 10 Hz IMU and a 10 Hz camera.

The guide's first cell names the URL and topics; a cell put in after it (as papermill's
parameters) points them at this test's bridge and topics.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import nbformat
import pytest
from nbclient import NotebookClient
from sensor_msgs.msg import Image, Imu

from roslibpy_lite import sync
from tests import notebooks
from tests.helpers import ROOT, BridgeProcess, marked_blocks, wait_until

GUIDE = ROOT / "docs" / "guides" / "notebooks.md"


@pytest.fixture
def robot(bridge: BridgeProcess, ros_node: Any, topic: str) -> tuple[str, str]:
    """rclpy publishing a 10 Hz IMU (frame imu_link) and a 10 Hz 32x24 rgb8 camera, once the
    bridge's graph lists both (as a robot's topics are when a user opens the notebook)."""
    imu_pub = ros_node.create_publisher(Imu, topic + "_imu", 10)
    cam_pub = ros_node.create_publisher(Image, topic + "_camera", 10)
    count = 0

    def tick() -> None:
        nonlocal count
        count += 1
        imu = Imu()
        imu.header.stamp = ros_node.get_clock().now().to_msg()
        imu.header.frame_id = "imu_link"
        imu.linear_acceleration.z = 9.81
        imu.angular_velocity.z = math.sin(count / 10)
        imu_pub.publish(imu)
        frame = Image(height=24, width=32, encoding="rgb8", step=96, data=bytes(range(96)) * 24)
        frame.header = imu.header
        cam_pub.publish(frame)

    ros_node.create_timer(0.1, tick)
    names = {topic + "_imu": "sensor_msgs/msg/Imu", topic + "_camera": "sensor_msgs/msg/Image"}
    with sync.connect(bridge.url, replace=False) as ros:
        wait_until(lambda: names.items() <= {(t.name, t.type) for t in ros.graph.topics()},
                   20, "the bridge's graph listing the robot's topics")
    return topic + "_imu", topic + "_camera"


def test_the_guide_runs_in_a_kernel(bridge: BridgeProcess, robot: tuple[str, str],
                                    tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every cell runs; each prints what the guide says, the callback's lines land in the
    cell that subscribed, the state line and the plot are displayed."""
    imu, camera = robot
    notebooks.kernel_env(monkeypatch, tmp_path, url=bridge.url, imu=imu, camera=camera)
    cells = [code for kind, code in marked_blocks(GUIDE, "notebook") if kind == "cell"]
    assert cells[0].startswith("URL = ") and len(cells) >= 8
    parameters = ("import os\nURL = os.environ['ROSLIBPY_LITE_NOTEBOOK_URL']\n"
                  "IMU = os.environ['ROSLIBPY_LITE_NOTEBOOK_IMU']\n"
                  "CAMERA = os.environ['ROSLIBPY_LITE_NOTEBOOK_CAMERA']")
    sources = [cells[0], parameters, *cells[1:]]
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(c) for c in sources])  # type: ignore[no-untyped-call]
    client = NotebookClient(nb, km=notebooks.kernel_manager(tmp_path), timeout=120,
                            resources={"metadata": {"path": str(ROOT)}})
    client.execute(cleanup_kc=True)
    out = {c.source.splitlines()[0]: c for c in nb.cells}

    def printed(first_line: str) -> str:
        return notebooks.stdout_of(out[first_line])

    assert printed("import roslibpy_lite") == "state: connected\n"
    state = [o for o in out["from roslibpy_lite import jupyter"].outputs
             if o["output_type"] == "display_data"]
    assert state and state[0]["data"]["text/plain"].startswith("robot: connected since ")
    assert printed("for topic in await ros.graph.topics():") == (
        f"{camera} sensor_msgs/msg/Image\n{imu} sensor_msgs/msg/Imu\n")
    assert printed("import asyncio") == "callback: imu z acceleration 9.81\n" * 3
    assert printed("from roslibpy_lite import sync") == "frame: imu_link\nnodes: True\n"
    assert printed("from roslibpy_lite.data import to_dataframe, to_numpy") == (
        "rows: 20 columns: ['linear_acceleration.z', 'angular_velocity.z'] index: time\n"
        "frame: (24, 32, 3) uint8\n")
    plot = out["import matplotlib.pyplot as plt"]
    assert notebooks.stdout_of(plot) == "plotted 30 samples\n"
    assert any("image/png" in o.get("data", {}) for o in plot.outputs), plot.outputs
    assert printed("msg, age = imu_sub.latest()") == (
        "latest: imu_link under a second old: True\nfresh: imu_link collected: True\ntime\n")
    again = out["robot = sync.connect(URL)  # the blocking client's cell, run again"]
    assert notebooks.stdout_of(again) == "connected: True\n"
    assert "ReplacedClientWarning" in _stderr(again) and bridge.url in _stderr(again)
    assert printed("ticks = []") == "open subscriptions: 1\n"
    assert "DuplicateCallbackWarning" in _stderr(out["ticks = []"])
    broken = out["def broken(msg):"]  # one traceback, then one count (issue 42)
    assert _stderr(broken).count("Traceback") == 1 and " more time" in _stderr(broken)
    assert f"did you mean '{imu}'?" in printed("typo = await ros.subscribe(IMU.upper(), "
                                              "\"sensor_msgs/msg/Imu\")")
    assert notebooks.stdout_of(nb.cells[-1]) == "state: closed\n"


def _stderr(cell: Any) -> str:
    return "".join(o.get("text", "") for o in cell.outputs
                   if o.get("output_type") == "stream" and o.get("name") == "stderr")
