"""Only the rclpy backend (bridge_server/rclpy_graph/) imports ROS, and the session layer
never imports the backend: the seam a ROS-free relay builds on (issue 26).

Imports are read from the source (ast), at any depth: module level, inside functions,
and under ``if TYPE_CHECKING:`` too.
"""

from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.core.test_import_cycles import ROOT, _module_name, _runtime_imports

BACKEND = "bridge_server.rclpy_graph"
ROS_FREE = ("roslibpy_lite", "msgs", "rosbridge_core", "bridge_server")
"""Packages whose modules (the backend's aside) must not import ROS."""
SESSION_SIDE = ("rosbridge_core.session", "bridge_server.http", "rosbridge_core.security",
                "rosbridge_core.graph", "rosbridge_core.interfaces", "rosbridge_core.codec",
                "bridge_server.zenoh")
"""What a relay without ROS runs: it must not reach the backend."""


def _imports(source: str, name: str, is_package: bool) -> set[str]:
    """Every module ``source`` imports, by absolute name, wherever the import stands."""
    package = name if is_package else name.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                module = ".".join([*base, node.module] if node.module else base)
            else:
                module = node.module or ""
            found.add(module)
            found.update(f"{module}.{a.name}" for a in node.names)
    return found


def _ros_packages() -> set[str]:
    """Python top-level names the ROS install provides: rclpy and every package the ament
    index lists (message packages, rosidl_*, rcl_interfaces, ...)."""
    names = {"rclpy", "rosidl_parser", "rosidl_runtime_py", "rpyutils"}
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    for prefix in [*prefixes, sys.prefix]:
        index = Path(prefix) / "share" / "ament_index" / "resource_index" / "packages"
        if index.is_dir():
            names.update(p.name for p in index.iterdir())
    return names


def _modules(packages: tuple[str, ...]) -> dict[str, Path]:
    return {
        _module_name(p): p
        for pkg in packages
        for p in (ROOT / pkg).rglob("*.py")
        if "generated" not in p.parts
    }


def _all_imports() -> dict[str, set[str]]:
    return {
        name: _imports(path.read_text(), name, path.name == "__init__.py")
        for name, path in _modules(ROS_FREE).items()
    }


def _ros_importers(imports: dict[str, set[str]], ros: set[str]) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    for name, targets in imports.items():
        if name == BACKEND or name.startswith(BACKEND + "."):
            continue
        bad = sorted(t for t in targets if t.split(".")[0] in ros)
        if bad:
            out[name] = bad
    return out


def _runtime_graph() -> dict[str, set[str]]:
    files = _modules(ROS_FREE)
    return {name: _runtime_imports(path, name, set(files)) for name, path in files.items()}


def _reaches_backend(imports: dict[str, set[str]]) -> dict[str, list[str]]:
    """Session-side modules that import the backend, or import one that does (through any
    chain of project modules), as module -> the chain."""
    out: dict[str, list[str]] = {}
    for start in imports:
        if not start.startswith(SESSION_SIDE):
            continue
        seen = {start}
        todo = [[start]]
        while todo:
            chain = todo.pop(0)
            for target in sorted(imports.get(chain[-1], ())):
                if target == BACKEND or target.startswith(BACKEND + "."):
                    out.setdefault(start, [*chain, target])
                    break
                if target in imports and target not in seen:
                    seen.add(target)
                    todo.append([*chain, target])
    return out


def test_the_checker_sees_every_kind_of_import() -> None:
    """Module level, inside a function, under TYPE_CHECKING, relative: all are seen."""
    source = (
        "from typing import TYPE_CHECKING\n"
        "import rclpy.node\n"
        "if TYPE_CHECKING:\n    from rclpy.qos import QoSProfile\n"
        "def f():\n    from action_msgs.msg import GoalStatus\n"
        "from ..rclpy_graph import convert\n"
    )
    found = _imports(source, "bridge_server.http.example", False)
    assert {"rclpy.node", "rclpy.qos", "action_msgs.msg", "bridge_server.rclpy_graph.convert"} <= found
    ros = {"rclpy", "action_msgs"}
    assert _ros_importers({"bridge_server.http.example": found}, ros) == {
        "bridge_server.http.example": ["action_msgs.msg", "action_msgs.msg.GoalStatus",
                                       "rclpy.node", "rclpy.qos", "rclpy.qos.QoSProfile"]
    }
    chain = {"bridge_server.http.web": {"bridge_server.front.server"},
             "bridge_server.front.server": {"bridge_server.rclpy_graph.graph"}}
    assert _reaches_backend(chain) == {
        "bridge_server.http.web": ["bridge_server.http.web", "bridge_server.front.server",
                                   "bridge_server.rclpy_graph.graph"]
    }


def test_the_ros_packages_are_known() -> None:
    """The ament index of the venv lists the ROS packages the backend imports."""
    ros = _ros_packages()
    assert {"rclpy", "action_msgs", "rcl_interfaces", "unique_identifier_msgs"} <= ros


def test_only_the_rclpy_backend_imports_ros() -> None:
    """Nothing in roslibpy_lite, msgs, rosbridge_core or bridge_server outside rclpy_graph/ imports rclpy
    or any other ROS package."""
    bad = _ros_importers(_all_imports(), _ros_packages())
    assert not bad, f"ROS imported outside {BACKEND}: {bad}"


@pytest.mark.parametrize("side", SESSION_SIDE)
def test_the_session_side_does_not_import_the_backend(side: str) -> None:
    """The sessions, rosapi, the status page and security hold a Graph, never the rclpy
    backend: they import none of it (of any kind: for type checking too), and what they
    import at run time does not either, through any chain of modules."""

    def mine(found: dict[str, list[str]]) -> dict[str, list[str]]:
        return {k: v for k, v in found.items() if k == side or k.startswith(side + ".")}

    direct = mine({k: [t for t in v if t == BACKEND or t.startswith(BACKEND + ".")]
                   for k, v in _all_imports().items()})
    direct = {k: v for k, v in direct.items() if v}
    assert not direct, f"{side} imports {BACKEND}: {direct}"
    chains = mine(_reaches_backend(_runtime_graph()))
    assert not chains, f"{side} reaches {BACKEND} at run time: {chains}"


OP_GROUPS = ("rosbridge_core.session.topics", "rosbridge_core.session.services",
             "rosbridge_core.session.actions", "rosbridge_core.session.rosapi")
WHOLE = ("bridge_server.front.server", "rosbridge_core.session.session")


@pytest.mark.parametrize("group", OP_GROUPS)
def test_the_op_groups_hold_a_narrow_handle(group: str) -> None:
    """An op group gets a SessionView (session/host.py), never the Session class or the bridge:
    it imports neither (for type checking neither)."""
    found = _all_imports()[group]
    bad = sorted(t for t in found if t in WHOLE or t.startswith(tuple(w + "." for w in WHOLE)))
    assert not bad, f"{group} imports {bad}"


RELAY_IMPORTS = ("bridge_server.zenoh.relay", "bridge_server.front.server",
                 "rosbridge_core.session.session", "rosbridge_core.security",
                 "bridge_server.http.web", "rosbridge_core.codec.cdr_json")
"""What ``roslibpy-lite-relay`` runs: its entry module and the bridge's server, sessions,
security and HTTP code."""


def test_the_relay_runs_where_ros_is_not_installed() -> None:
    """In a Python where rclpy and every ROS package cannot be imported, the relay's entry
    module, the server, the sessions, security, HTTP and the codecs import, and parse the
    relay's command line; the rclpy backend is never loaded."""
    code = (
        "import json, sys\n"
        "for name in json.loads(sys.argv[1]):\n"
        "    sys.modules[name] = None  # import rclpy (or any ROS package): ImportError\n"
        "import importlib\n"
        "for module in json.loads(sys.argv[2]):\n"
        "    importlib.import_module(module)\n"
        "from bridge_server.zenoh.relay import parse_args\n"
        "args = parse_args(['--zenoh-listen', 'tcp/127.0.0.1:7447', '--port', '0'])\n"
        "assert args.zenoh_listen == ['tcp/127.0.0.1:7447']\n"
        "print(json.dumps(sorted(m for m in sys.modules if m.startswith('bridge_server'))))\n"
    )
    blocked = sorted(_ros_packages())
    done = subprocess.run(
        [sys.executable, "-c", code, json.dumps(blocked), json.dumps(RELAY_IMPORTS)],
        cwd=ROOT, capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 0, done.stderr
    loaded = json.loads(done.stdout.strip().splitlines()[-1])
    assert "bridge_server.zenoh.relay" in loaded and "bridge_server.front.server" in loaded
    assert not [m for m in loaded if m.startswith(BACKEND)], loaded
