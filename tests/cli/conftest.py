"""Helpers for the CLI tests: run ``main(argv)`` in this process and collect what it printed."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import pytest

from roslibpy_lite.cli import main
from tests.bridge.support import serve_mult
from tests.cli.ros2_nodes import managed_node, param_node  # noqa: F401 - fixtures for tests here
from tests.helpers import BridgeProcess, free_port


@dataclass
class Result:
    """What one run of the CLI returned and printed."""

    code: int
    out: str
    err: str

    @property
    def lines(self) -> list[str]:
        """stdout, line by line."""
        return self.out.splitlines()


Run = Callable[..., Result]


@pytest.fixture
def multiplier(ros_node: Any, topic: str) -> str:
    """An rclpy mult_msgs/srv/MultFloats server named ``topic``; returns the service name."""
    serve_mult(ros_node, topic)
    return topic


@pytest.fixture
def cli(bridge: BridgeProcess, capsys: pytest.CaptureFixture[str]) -> Run:
    """``cli("topic", "list")``: run the CLI against the session bridge (``url=None``: no --url)."""

    def run(*argv: str, url: str | None = bridge.url) -> Result:
        capsys.readouterr()
        code = main([*argv, "--url", url] if url is not None else list(argv))
        captured = capsys.readouterr()
        return Result(code, captured.out, captured.err)

    return run


def closed_port() -> int:
    """A port nothing listens on (nor will: :func:`tests.helpers.free_port`)."""
    return free_port()


def one_error_line(result: Result, code: int, *fragments: str) -> None:
    """The run failed with ``code``, printed nothing on stdout and one line on stderr."""
    assert result.code == code, result
    assert result.out == "", result
    lines = result.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("roslibpy-lite: "), result
    for fragment in fragments:
        assert fragment in lines[0], result
