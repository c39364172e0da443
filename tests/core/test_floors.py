"""The floors of docs/architecture.md hold in the code: each module imports only modules of
its own floor or below (type-checking imports and imports inside functions too), and the
client and the server, two towers on the core, never import each other (issue 51)."""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass

from tests.core.test_ros_boundary import _imports, _modules
from tests.helpers import ROOT

PAGE = ROOT / "docs" / "architecture.md"
PACKAGES = ("msgs", "rosbridge_core", "roslibpy_lite", "bridge_server", "bench")


@dataclass(frozen=True)
class Floor:
    """One floor: its height (0 at the bottom) and its tower (``""``: shared by both)."""

    level: int
    tower: str
    """``client`` or ``server``; ``""``: shared (the core below both); ``both``: on top of
    both towers (the benchmarks)."""

    def may_import(self, other: Floor) -> bool:
        """Down or level, in this floor's tower or a shared one (from on top of both: any)."""
        return other.level <= self.level and (
            self.tower == "both" or other.tower in ("", self.tower))


def floors_of(text: str) -> dict[str, Floor]:
    """The floor of each name (package or module) the page's list gives, bottom first."""
    block = re.search(r"<!-- floors -->\n(.*?)<!-- /floors -->", text, re.S)
    assert block, "docs/architecture.md has no <!-- floors --> list"
    names: dict[str, Floor] = {}
    for level, line in enumerate(block.group(1).strip().splitlines()):
        m = re.fullmatch(r"- (?:(client|server|both): )?(.+)", line.strip())
        assert m, f"not a floor line: {line!r}"
        for name in re.findall(r"`([\w.]+)`", m.group(2)):
            names[name] = Floor(level, m.group(1) or "")
    return names


def floor_of(module: str, floors: dict[str, Floor]) -> Floor | None:
    """The floor of the longest name in ``floors`` that is ``module`` or a package of it."""
    parts = module.split(".")
    for n in range(len(parts), 0, -1):
        floor = floors.get(".".join(parts[:n]))
        if floor is not None:
            return floor
    return None


def stray_imports(imports: dict[str, set[str]], floors: dict[str, Floor]) -> list[str]:
    """Every import (of a module of ours) that runs up a floor or across the towers."""
    bad = []
    for module, targets in sorted(imports.items()):
        here = floor_of(module, floors)
        assert here is not None, f"{module} is on no floor of docs/architecture.md"
        for target in sorted(targets):
            there = floor_of(target, floors)
            if there is not None and not here.may_import(there):
                bad.append(f"{module} -> {target}")
    return bad


def _imports_of(folders: tuple[str, ...]) -> dict[str, set[str]]:
    """Every module of ``folders`` with what it imports (any kind of import)."""
    return {name: _imports(path.read_text(), name, path.name == "__init__.py")
            for name, path in _modules(folders).items()}


@functools.cache
def _read_imports() -> dict[str, frozenset[str]]:
    return {name: frozenset(found) for name, found in _imports_of(PACKAGES).items()}


def _all_imports() -> dict[str, set[str]]:
    return {name: set(targets) for name, targets in _read_imports().items()}


def test_no_import_runs_up_a_floor_or_across_the_towers() -> None:
    """Drawn from its imports, the repository has no arrow that runs back up, and neither the
    client nor the server imports the other."""
    floors = floors_of(PAGE.read_text())
    assert {"msgs", "rosbridge_core.protocol", "roslibpy_lite", "bridge_server.zenoh",
            "bench"} <= set(floors)
    assert stray_imports(_all_imports(), floors) == []


def test_the_session_tests_stand_on_the_core_alone() -> None:
    """tests/session runs the core's session over the core's memory Graph and link: it
    imports nothing of the server or the client (a test of theirs belongs in their folder)."""
    floors = floors_of(PAGE.read_text())
    session_tests = _imports_of(("tests/session",))
    assert session_tests, "no tests in tests/session"
    bad = sorted(f"{module} -> {target}" for module, targets in session_tests.items()
                 for target in targets
                 if (floor := floor_of(target, floors)) is not None and floor.tower)
    assert bad == []


def test_one_stray_import_is_found() -> None:
    """The checker names one upward import, one across the towers and one type-checking
    import, each added to the real graph."""
    floors = floors_of(PAGE.read_text())
    imports = _all_imports()
    typing_only = _imports(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
        "    from rosbridge_core.session.session import Session\n",
        "rosbridge_core.security.gate", False)
    imports["rosbridge_core.security.gate"] |= typing_only
    imports["rosbridge_core.protocol.ops"] |= {"roslibpy_lite.ros"}
    imports["bridge_server.http.web"] |= {"roslibpy_lite"}
    assert stray_imports(imports, floors) == [
        "bridge_server.http.web -> roslibpy_lite",
        "rosbridge_core.protocol.ops -> roslibpy_lite.ros",
        "rosbridge_core.security.gate -> rosbridge_core.session.session",
        "rosbridge_core.security.gate -> rosbridge_core.session.session.Session",
    ]


def test_the_floor_rules() -> None:
    """Down and level are allowed, up is not; a tower may use the shared floors, not the
    other tower, even one lower."""
    core, client, server = Floor(1, ""), Floor(5, "client"), Floor(6, "server")
    assert Floor(9, "both").may_import(client) and Floor(9, "both").may_import(server)
    assert client.may_import(core) and server.may_import(core)
    assert not core.may_import(client)
    assert not server.may_import(client) and not client.may_import(server)
    assert Floor(6, "server").may_import(Floor(5, "server"))
    assert not Floor(5, "server").may_import(Floor(6, "server"))
