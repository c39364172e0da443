"""The README's code runs as written: each marked Python block, as a user would run it."""

from __future__ import annotations

import re
import subprocess
import sys

from tests.helpers import ROOT, BridgeProcess, ros_env

BLOCK = re.compile(r"<!-- readme-test: (\w+) -->\n```python\n(.*?)```", re.S)
BLOCKS = {kind: code for kind, code in BLOCK.findall((ROOT / "README.md").read_text())}


def _run(code: str) -> str:
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, env=ros_env(), capture_output=True, text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    return done.stdout


def test_readme_has_its_examples() -> None:
    """The README carries both tested examples."""
    assert set(BLOCKS) == {"bridge", "mock"}


def test_client_example_runs_against_the_bridge(bridge: BridgeProcess) -> None:
    """The client example serves and calls a service and gets a latched typed message."""
    out = _run(BLOCKS["bridge"].replace("ws://127.0.0.1:9090", bridge.url))
    assert "2.5 * 4.0 = 10.0" in out
    assert "got Int16(data=3)" in out


def test_mock_example_runs() -> None:
    """The MockRos example passes its own assertion."""
    assert "MockRos test passed" in _run(BLOCKS["mock"])
