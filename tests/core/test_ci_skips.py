"""Under CI=true a skipped test fails, so a missing Node.js or Chromium cannot pass CI silently."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
_SKIPPING = '''
import pytest


def test_needs_a_tool():
    """Stands for a test whose tool is missing."""
    pytest.skip("node is not on PATH")
'''


def _run(tmp_path: Path, ci: str) -> subprocess.CompletedProcess[str]:
    test = tmp_path / "test_skipping.py"
    test.write_text(_SKIPPING)
    env = dict(os.environ, CI=ci)
    return subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "tests.conftest",
         "--rootdir", str(tmp_path), "-c", os.devnull, str(test)],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=60,
    )


def test_skip_fails_under_ci(tmp_path: Path) -> None:
    """With CI=true the skip is reported as a failure that names the missing tool."""
    run = _run(tmp_path, "true")
    assert run.returncode == 1, run.stdout + run.stderr
    assert "skipped under CI=true" in run.stdout and "node is not on PATH" in run.stdout


def test_skip_stays_a_skip_outside_ci(tmp_path: Path) -> None:
    """Without CI the same test is an ordinary skip."""
    run = _run(tmp_path, "")
    assert run.returncode == 0, run.stdout + run.stderr
    assert "1 skipped" in run.stdout
