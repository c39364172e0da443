"""Under CI=true a skipped test fails, so a missing Node.js or Chromium cannot pass CI silently."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
_SKIPPING = '''
import pytest


def test_needs_a_tool():
    """Stands for a test whose tool is missing."""
    pytest.skip("node is not on PATH")
'''


_MODULE_SKIPS = {
    "importorskip": 'import pytest\n\npytest.importorskip("no_such_module_for_ci")\n\n\n'
                    'def test_it():\n    """Never collected."""\n',
    "skip": 'import pytest\n\npytest.skip("chromium is not installed", allow_module_level=True)'
            '\n\n\ndef test_it():\n    """Never collected."""\n',
}


def _run(tmp_path: Path, ci: str, source: str = _SKIPPING) -> subprocess.CompletedProcess[str]:
    test = tmp_path / "test_skipping.py"
    test.write_text(source)
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


@pytest.mark.parametrize(("how", "why"), [("importorskip", "no_such_module_for_ci"),
                                          ("skip", "chromium is not installed")])
def test_a_module_skipped_at_collection_fails_under_ci(tmp_path: Path, how: str,
                                                       why: str) -> None:
    """A module-level importorskip or skip(allow_module_level=True) fails the CI run, naming
    the module and the reason; outside CI it stays a skip."""
    run = _run(tmp_path, "true", _MODULE_SKIPS[how])
    assert run.returncode not in (0, 5), run.stdout + run.stderr
    assert "test_skipping.py skipped at collection under CI=true" in run.stdout, run.stdout
    assert why in run.stdout
    run = _run(tmp_path, "", _MODULE_SKIPS[how])
    assert "1 skipped" in run.stdout and "error" not in run.stdout, run.stdout + run.stderr
    assert run.returncode == 5, run.stdout + run.stderr  # pytest's "no tests ran"
