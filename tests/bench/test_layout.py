"""bench/'s modules import the harness, never the runner that imports them (issue 30)."""

from __future__ import annotations

import ast
from pathlib import Path

BENCH = Path(__file__).resolve().parents[2] / "bench"


def _imported(path: Path) -> set[str]:
    """Every module ``path`` imports, type-checking-only imports included."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            found.add(node.module)
    return found


def test_no_scenario_module_imports_the_runner() -> None:
    """Only ``python -m bench``'s entry imports ``bench.run``, so there is no circle even for mypy."""
    offenders = sorted(
        p.name for p in BENCH.glob("*.py")
        if p.name not in ("__main__.py", "run.py") and "bench.run" in _imported(p)
    )
    assert not offenders, f"bench modules importing bench.run: {offenders}"
