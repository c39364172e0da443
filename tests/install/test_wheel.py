"""The client installs from a wheel on a machine without ROS, and works there.

The wheel is built with the documented command (``pip wheel --no-deps``)
from a copy of the sources, installed into a clean virtual environment
(``python -m venv``; websockets comes from PyPI or pip's cache), and then the
CLI, a blocking script and an unchanged roslibpy script run against the real
bridge. The repository is not on that environment's path.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.helpers import ROOT, BridgeProcess

SOURCES = ["pyproject.toml", "README.md", "roslibpy_lite", "rosbridge_core", "bridge_server", "msgs"]

SYNC_SCRIPT = """
import sys
from roslibpy_lite import sync

with sync.connect(sys.argv[1]) as ros:
    topics = ros.call_service("/rosapi/topics", "rosapi_msgs/srv/Topics", timeout=10)
    print("topics via a blocking call:", "/rosout" in topics["topics"])
"""

CBOR_SCRIPT = """
import sys
from roslibpy_lite import sync

with sync.connect(sys.argv[1]) as ros:
    ros.advertise("/wheel_cbor", "std_msgs/msg/String", latch=True).publish({"data": "packed"})
    with ros.subscribe("/wheel_cbor", "std_msgs/msg/String", compression="cbor") as sub:
        print("cbor:", sub.get(timeout=15))
"""

MOCK_SCRIPT = """
import asyncio
from roslibpy_lite import MockRos, GoalStatus

async def count(goal, ctx):
    ctx.publish_feedback({"elapsed": 0.5})
    return {"samples": goal["seconds"] * 2}

async def main():
    async with MockRos() as ros:
        sub = ros.subscribe("/chat", "std_msgs/msg/String")
        await ros.advertise("/chat", "std_msgs/msg/String").publish({"data": "hi"})
        print("topic:", (await sub.get(1))["data"])
        ros.advertise_service("/mult", "mult_msgs/srv/MultFloats",
                              lambda req: {"result": req["x"] * req["y"]})
        answer = await ros.call_service("/mult", "mult_msgs/srv/MultFloats", {"x": 2.0, "y": 3.0})
        print("service:", answer["result"])
        await ros.advertise_action("/imu", "mult_msgs/action/IntegrateImu", count)
        goal = await ros.send_goal("/imu", "mult_msgs/action/IntegrateImu", {"seconds": 2.0})
        outcome = await goal.result(timeout=5)
        print("action:", outcome.status is GoalStatus.SUCCEEDED, outcome.values["samples"])
        print("graph:", [t.name for t in await ros.graph.topics()])

asyncio.run(main())
"""


@dataclass
class Venv:
    """A clean virtual environment with the wheel installed."""

    root: Path
    work: Path

    def bin(self, name: str) -> str:
        """The path of an executable in the environment."""
        return str(self.root / "bin" / name)

    def run(self, *args: str, check: bool = True, **extra: str) -> subprocess.CompletedProcess[str]:
        """Run a command of the environment, from a directory outside the repository."""
        env = {k: v for k, v in os.environ.items()
               if k not in ("PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME")}
        env.update(PYTHONUNBUFFERED="1", **extra)
        done = subprocess.run(list(args), cwd=self.work, env=env, capture_output=True, text=True,
                              timeout=60)
        if check:
            assert done.returncode == 0, done.stdout + done.stderr
        return done


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The wheel, built with the documented command from a copy of the sources."""
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "src"
    src.mkdir()
    ignore = shutil.ignore_patterns("__pycache__", "*.egg-info", "build")
    for name in SOURCES:
        path = ROOT / name
        if path.is_dir():
            shutil.copytree(path, src / name, ignore=ignore)
        else:
            shutil.copy2(path, src / name)
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w",
                    str(tmp / "dist"), str(src)], check=True, capture_output=True, timeout=120)
    return next((tmp / "dist").glob("roslibpy_lite-*.whl"))


def make_venv(tmp: Path, requirement: str) -> Venv:
    """A fresh venv in ``tmp`` with ``requirement`` (the wheel, maybe with extras) installed."""
    subprocess.run([sys.executable, "-m", "venv", str(tmp / "venv")], check=True, timeout=120)
    env = Venv(tmp / "venv", tmp)
    env.run(env.bin("pip"), "install", "-q", requirement)
    return env


def installed(venv: Venv) -> set[str]:
    """The distributions in ``venv`` besides pip and setuptools."""
    listed = json.loads(venv.run(venv.bin("pip"), "list", "--format=json").stdout)
    return {p["name"].lower() for p in listed} - {"pip", "setuptools"}


@pytest.fixture(scope="module")
def venv(wheel: Path, tmp_path_factory: pytest.TempPathFactory) -> Venv:
    """A clean venv with the wheel alone installed."""
    return make_venv(tmp_path_factory.mktemp("venv"), str(wheel))


def test_only_websockets_comes_in(venv: Venv) -> None:
    """Installing the wheel brings websockets and nothing else (no ROS, numpy, cbor2, yaml)."""
    assert installed(venv) == {"roslibpy-lite", "websockets"}


def test_extras_bring_only_their_packages(wheel: Path, tmp_path: Path, bridge: BridgeProcess) -> None:
    """With [cli,cbor] only pyyaml and cbor2 come in too; YAML values and CBOR then work."""
    venv = make_venv(tmp_path, f"{wheel}[cli,cbor]")
    assert installed(venv) == {"roslibpy-lite", "websockets", "pyyaml", "cbor2"}
    typed = venv.run(venv.bin("roslibpy-lite"), "--url", bridge.url, "service", "call",
                     "/rosapi/topic_type", "rosapi_msgs/srv/TopicType", "{topic: /rosout}")
    assert "rcl_interfaces/msg/Log" in typed.stdout
    cbor = venv.run(venv.bin("python"), "-c", CBOR_SCRIPT, bridge.url)
    assert "cbor: {'data': 'packed'}" in cbor.stdout


def test_cli_and_scripts_work_against_the_bridge(venv: Venv, bridge: BridgeProcess) -> None:
    """The CLI lists topics, a blocking script calls a service, a roslibpy script connects."""
    cli = venv.run(venv.bin("roslibpy-lite"), "--url", bridge.url, "topic", "list")
    assert "/rosout" in cli.stdout
    blocking = venv.run(venv.bin("python"), "-c", SYNC_SCRIPT, bridge.url)
    assert "topics via a blocking call: True" in blocking.stdout
    script = ROOT / "tests" / "compat" / "scripts" / "hello_world.py"
    roslibpy_script = venv.run(venv.bin("python"), str(script), ROSBRIDGE_PORT=str(bridge.port))
    assert "Is ROS connected? True" in roslibpy_script.stdout
    imported = venv.run(venv.bin("python"), "-c", "import roslibpy_lite; print(roslibpy_lite.__file__)")
    assert str(venv.root) in imported.stdout  # the wheel's copy, not the repository's


def test_mock_ros_runs_the_bridges_session_in_a_client_only_install(venv: Venv) -> None:
    """MockRos (the bridge's own session over an in-memory graph) publishes, serves and calls
    a service, runs an action goal and lists the graph with websockets alone installed."""
    done = venv.run(venv.bin("python"), "-c", MOCK_SCRIPT)
    assert done.stdout.splitlines() == [
        "topic: hi", "service: 6.0", "action: True 4", "graph: ['/chat']"], done.stdout


def test_bridge_without_its_extra_says_what_to_install(venv: Venv) -> None:
    """Starting the bridge in a client-only install fails with one line naming the extra."""
    done = venv.run(venv.bin("roslibpy-lite-bridge"), "--port", "0", check=False)
    assert done.returncode == 2
    assert "Traceback" not in done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "pip install '.[bridge]'" in lines[0], done.stderr
