"""Ctrl+C in a script: roslibpy_lite.run() ends it with status 130 and no traceback."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

SCRIPT = """
import asyncio, sys
import roslibpy_lite

async def main() -> None:
    async with roslibpy_lite.connect(sys.argv[1]) as ros:
        sub = await ros.subscribe("/clean_exit", "std_msgs/msg/String")
        print("ready", flush=True)
        async for msg in sub:
            print(msg)

{runner}(main())
"""

ROOT = Path(__file__).resolve().parents[2]


def _interrupt(tmp_path: Path, url: str, runner: str) -> tuple[int, str]:
    script = tmp_path / "script.py"
    script.write_text(SCRIPT.format(runner=runner))
    with subprocess.Popen(  # closes its pipes however the test ends
        [sys.executable, str(script), url], cwd=ROOT, text=True,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    ) as proc:
        try:
            assert proc.stdout is not None
            assert proc.stdout.readline().strip() == "ready"
            proc.send_signal(signal.SIGINT)
            _, err = proc.communicate(timeout=30)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    return proc.returncode, err


@pytest.mark.parametrize(("runner", "clean"), [("roslibpy_lite.run", True), ("asyncio.run", False)])
def test_ctrl_c_ends_a_script_cleanly(
    tmp_path: Path, bridge: Any, runner: str, clean: bool
) -> None:
    """With roslibpy_lite.run, SIGINT exits 130 without a traceback; bare asyncio.run shows one."""
    code, err = _interrupt(tmp_path, bridge.url, runner)
    if clean:
        assert code == 130, err
        assert "Traceback" not in err, err
    else:
        assert "Traceback" in err and "KeyboardInterrupt" in err
