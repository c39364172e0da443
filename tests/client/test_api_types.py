"""Both backends are Ros, as mypy --strict sees it."""

from __future__ import annotations

from pathlib import Path

import pytest

SNIPPET = '''
from typing import Any
from roslibpy_lite import Client, MockRos, Ros, Publisher, Subscription
from msgs.std_msgs.msg import String

def _check(r: Ros) -> None: ...

def use(c: Client) -> None:
    _check(MockRos())
    _check(c)

async def typed(r: Ros) -> None:
    pub: Publisher[String] = r.advertise("/a", String)
    await pub.publish(String(data="x"))
    sub: Subscription[String] = r.subscribe("/a", String)
    msg: String = await sub.get(1.0)
    raw: Subscription[dict[str, Any]] = r.subscribe("/b", "std_msgs/msg/String")
    reply: dict[str, Any] = await r.call_service("/s", "mult_msgs/srv/MultFloats", {"x": 1.0})
    del msg, raw, reply
'''

BROKEN = '''
from roslibpy_lite import Ros

class NotRos:
    async def close(self) -> None: ...

def _check(r: Ros) -> None: ...

_check(NotRos())
'''


def _mypy(tmp_path: Path, text: str) -> tuple[str, int]:
    api = pytest.importorskip("mypy.api")
    path = tmp_path / "snippet.py"
    path.write_text(text)
    root = Path(__file__).resolve().parents[2]
    out, err, status = api.run([
        "--strict", "--no-incremental", "--config-file", str(root / "pyproject.toml"), str(path)
    ])
    return out + err, status


def test_client_and_mock_are_ros(tmp_path: Path) -> None:
    """``_check(MockRos())`` and ``_check(client)`` type-check, and handle types follow the message type."""
    out, status = _mypy(tmp_path, SNIPPET)
    assert status == 0, out


def test_something_else_is_not_ros(tmp_path: Path) -> None:
    """The check can fail: a class lacking the API is rejected by mypy."""
    out, status = _mypy(tmp_path, BROKEN)
    assert status == 1 and "Ros" in out, out
