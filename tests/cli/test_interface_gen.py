"""``roslibpy-lite interface gen``: typed modules for the robot's own types, from the real
bridge's definitions, importable in a fresh interpreter with type hints and lookup by name."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from tests.cli.conftest import Run, one_error_line

CHECK = """
import sys
from robot_types.robot_msgs.msg import Status, Wheel
from robot_types.robot_msgs.srv import SetMode
from msgs.runtime import lookup
from msgs import cdr
from robot_msgs.msg import Status as RosStatus
from rclpy.serialization import deserialize_message
assert lookup("robot_msgs/msg/Status") is Status and lookup("robot_msgs/srv/SetMode") is SetMode
assert Status._fields_and_types == RosStatus.get_fields_and_field_types()
msg = Status(mode=Status.MODE_DRIVE, wheels=[Wheel(name="left", ticks=[1, 2, 3])])
ros = deserialize_message(cdr.encode(msg), RosStatus)
assert (ros.mode, ros.wheels[0].name, list(ros.wheels[0].ticks)) == (1, "left", [1, 2, 3])
assert SetMode.Response().status.label == "robot"
print("ok")
"""


def test_interface_gen_writes_an_importable_typed_package(cli: Run, tmp_path: Path) -> None:
    """Status, its Wheel and the SetMode service are written once each; standard types are
    imported from msgs; a fresh interpreter imports and uses them, and mypy reads them."""
    target = tmp_path / "robot_types"
    result = cli("interface", "gen", "robot_msgs/msg/Status", "robot_msgs/srv/SetMode",
                 "-o", str(target))
    assert result.code == 0, result
    assert "robot_msgs" in result.out
    files = sorted(p.relative_to(target).as_posix() for p in target.rglob("*.py"))
    assert files == ["__init__.py", "robot_msgs/__init__.py", "robot_msgs/msg.py",
                     "robot_msgs/srv.py"]
    msg_py = (target / "robot_msgs/msg.py").read_text()
    assert "from msgs.std_msgs import msg as _std_msgs_msg" in msg_py
    assert "class Wheel(Message)" in msg_py and "register(Status, Wheel)" in msg_py
    run = subprocess.run([sys.executable, "-c", CHECK], cwd=tmp_path, capture_output=True,
                         text=True, timeout=60)
    assert run.stdout.strip() == "ok", run.stderr
    repo = str(Path(__file__).resolve().parents[2])  # where mypy finds msgs (editable install)
    typed = subprocess.run([sys.executable, "-m", "mypy", "--strict", "--no-incremental",
                            "robot_types"], cwd=tmp_path, capture_output=True, text=True,
                           timeout=300, env={**os.environ, "MYPYPATH": repo})
    assert typed.returncode == 0, typed.stdout


def test_interface_gen_of_an_unknown_type_says_so(cli: Run, tmp_path: Path) -> None:
    """A type the robot lacks: one error line naming it, nothing written."""
    result = cli("interface", "gen", "nope_msgs/msg/Missing", "-o", str(tmp_path / "out"))
    one_error_line(result, 4, "nope_msgs/msg/Missing is not installed")
    assert not (tmp_path / "out" / "nope_msgs").exists()
