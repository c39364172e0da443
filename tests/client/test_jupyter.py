"""roslibpy_lite.jupyter outside a kernel (the kernel's side: tests/sync/test_notebook.py)."""

from __future__ import annotations

from typing import Any

import pytest

from roslibpy_lite import MockRos, jupyter


def test_outside_a_kernel_callbacks_are_left_alone() -> None:
    """No kernel: in_cell gives the callback itself."""
    def cb(msg: Any) -> None:
        pass

    assert not jupyter.in_kernel()
    assert jupyter.in_cell(cb) is cb


async def test_show_state_prints_outside_a_kernel(capsys: pytest.CaptureFixture[str]) -> None:
    """Outside a kernel show_state prints the state line at once and at each change."""
    async with MockRos() as ros:
        stop = jupyter.show_state(ros, label="mock")
        ros.disconnect()
        ros.reconnect()
        stop()
        ros.disconnect()
    lines = [line.split(" since ")[0] for line in capsys.readouterr().out.splitlines()]
    assert lines == ["mock: connected", "mock: reconnecting", "mock: connected"]
