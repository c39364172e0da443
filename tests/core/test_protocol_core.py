"""The protocol core (rosbridge_core.protocol) stands alone: it, and the bridge that uses it,
load no other module of the client; the client's public names load at their first use."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

from tests.core.test_import_cycles import _graph

ROOT = Path(__file__).resolve().parents[2]
CORE = "rosbridge_core.protocol"

LOADED = """
import importlib, pkgutil, sys
for name in {names!r}:
    module = importlib.import_module(name)
    if {walk!r} and hasattr(module, "__path__"):
        for info in pkgutil.walk_packages(module.__path__, name + "."):
            importlib.import_module(info.name)
print("\\n".join(sorted(m for m in sys.modules if m.split(".")[0] == "roslibpy_lite")))
"""


def _client_modules_loaded(*names: str, walk: bool = False) -> list[str]:
    """The roslibpy_lite modules a fresh interpreter holds after importing ``names`` (and,
    with ``walk``, every module below them), other than the core and the package's
    ``__init__``."""
    out = subprocess.run([sys.executable, "-c", LOADED.format(names=names, walk=walk)],
                         cwd=ROOT, capture_output=True, text=True, timeout=60, check=True)
    return [m for m in out.stdout.split()
            if m != "roslibpy_lite" and m != CORE and not m.startswith(CORE + ".")]


def test_the_core_imports_nothing_else_of_the_client() -> None:
    """Importing the protocol core and each of its modules loads no other client module."""
    assert _client_modules_loaded(CORE, walk=True) == []


def test_the_core_names_nothing_else_of_the_client_even_for_type_checking() -> None:
    """No module of the core imports a client module, not even under ``TYPE_CHECKING``."""
    graph = _graph(type_level=True)
    reaches = {module: sorted(t for t in targets if t.startswith("roslibpy_lite")
                              and t != CORE and not t.startswith(CORE + "."))
               for module, targets in graph.items()
               if module == CORE or module.startswith(CORE + ".")}
    assert len(reaches) >= 5 and not any(reaches.values()), reaches


def test_the_bridge_loads_only_the_core_of_the_client() -> None:
    """Importing bridge_server, its session and every other module of it loads no client
    module beyond the protocol core."""
    assert _client_modules_loaded("rosbridge_core.session.session") == []
    assert _client_modules_loaded("bridge_server", walk=True) == []


FIRST_USE = """
import sys, roslibpy_lite
print(sorted(m for m in sys.modules if m.startswith("roslibpy_lite")))
print(roslibpy_lite.sync.__name__)
try:
    roslibpy_lite.no_such_name
except AttributeError as exc:
    print(exc)
"""


def test_the_package_loads_the_client_at_the_first_use_of_a_name() -> None:
    """``import roslibpy_lite`` alone loads only the package; each name of ``__all__`` then
    resolves to what its ``TYPE_CHECKING`` import in ``__init__`` names, a submodule
    resolves by its name, and an unknown name is an AttributeError."""
    out = subprocess.run([sys.executable, "-c", FIRST_USE], cwd=ROOT, capture_output=True,
                         text=True, timeout=60, check=True)
    loaded, submodule, unknown = out.stdout.splitlines()
    assert loaded == "['roslibpy_lite']"
    assert submodule == "roslibpy_lite.sync"
    assert unknown == "module 'roslibpy_lite' has no attribute 'no_such_name'"

    import importlib

    import roslibpy_lite

    init = ROOT / "roslibpy_lite" / "__init__.py"
    declared: dict[str, str] = {}
    for node in ast.walk(ast.parse(init.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            for alias in node.names:
                declared[alias.asname or alias.name] = f"roslibpy_lite.{node.module}"
    assert set(declared) == set(roslibpy_lite.__all__) - {"__version__"}
    for name, module in declared.items():
        assert getattr(roslibpy_lite, name) is getattr(importlib.import_module(module), name)
