"""No module imports another that imports it back: at run time in every package, and even
counting the imports made only for type checking in roslibpy_lite and bridge_server."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("msgs", "rosbridge_core", "roslibpy_lite", "bridge_server", "bench")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(path: Path, name: str, modules: set[str], type_level: bool) -> set[str]:
    """Project modules ``path`` imports at any depth (inside ``if TYPE_CHECKING:`` blocks
    too when ``type_level``)."""
    tree = ast.parse(path.read_text(), str(path))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()

    def resolve(level: int, module: str | None) -> str:
        if not level:
            return module or ""
        base = package.split(".")
        base = base[: len(base) - (level - 1)]
        return ".".join([*base, module] if module else base)

    def visit(node: ast.AST) -> None:
        for child in ast.iter_child_nodes(node):
            if (not type_level and isinstance(child, ast.If)
                    and "TYPE_CHECKING" in ast.unparse(child.test)):
                for other in child.orelse:
                    visit(other)
                continue
            if isinstance(child, ast.Import):
                targets = [a.name for a in child.names]
            elif isinstance(child, ast.ImportFrom):
                base = resolve(child.level, child.module)
                targets = [f"{base}.{a.name}" for a in child.names] + [base]
            else:
                visit(child)
                continue
            for t in targets:
                while t and t not in modules:  # "pkg.mod.func" -> "pkg.mod"
                    t = t.rpartition(".")[0]
                if t and t != name:
                    found.add(t)

    visit(tree)
    return found


def _runtime_imports(path: Path, name: str, modules: set[str]) -> set[str]:
    """Project modules ``path`` imports outside ``if TYPE_CHECKING:`` blocks, at any depth."""
    return _imports(path, name, modules, type_level=False)


def _graph(type_level: bool = False) -> dict[str, set[str]]:
    files = {_module_name(p): p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")}
    modules = set(files)
    graph = {name: _imports(path, name, modules, type_level) for name, path in files.items()}
    for name in graph:  # a package's __init__ is not a cycle partner of its own submodules
        graph[name] = {t for t in graph[name] if not name.startswith(t + ".")}
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def strong(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            strong(v)
    return out


def test_the_checker_finds_a_cycle() -> None:
    """The checker itself reports a cycle when there is one."""
    assert _cycles({"a": {"b"}, "b": {"a"}, "c": {"a"}}) == [["a", "b"]]


@pytest.mark.parametrize("package", PACKAGES)
def test_no_runtime_import_cycles(package: str) -> None:
    """Modules of each package (and across packages) import each other in one direction only."""
    cycles = [c for c in _cycles(_graph()) if any(m.split(".")[0] == package for m in c)]
    assert not cycles, f"runtime import cycles: {cycles}"


def test_the_type_level_graph_counts_type_checking_imports() -> None:
    """The bag player imports api only for type checking: an edge at type level, none at run
    time."""
    assert "roslibpy_lite.api" in _graph(type_level=True)["roslibpy_lite.bag.player"]
    assert "roslibpy_lite.api" not in _graph()["roslibpy_lite.bag.player"]


@pytest.mark.parametrize("package", ["rosbridge_core", "roslibpy_lite", "bridge_server"])
def test_no_type_level_import_cycles(package: str) -> None:
    """Counting the imports made only for type checking, each package's modules import each
    other in one direction only: each seam a small protocol (a session's link and shared
    state, the gate's session, the status's bridge), never a reach back to ``Bridge`` or
    ``Session``."""
    cycles = [c for c in _cycles(_graph(type_level=True))
              if any(m.split(".")[0] == package for m in c)]
    assert not cycles, f"type-level import cycles: {cycles}"
