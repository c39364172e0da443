"""Jazzy's and Kilted's wheels describe every interface type they share alike: the RIHS01 type
hash of each (from the type descriptions rosidl installs, share/PKG/msg|srv|action/*.json) is
the same in both venvs, the custom interfaces built into each included. This is what lets a
Jazzy and a Kilted node meet on one topic without a type-hash mismatch (docs/distributions.md).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from tests.distro.support import VENVS, other_distro, other_python


def type_hashes(prefix: Path) -> dict[str, str]:
    """Every type's RIHS01 hash the venv at ``prefix`` has a description of."""
    out: dict[str, str] = {}
    for path in prefix.glob("share/*/*/*.json"):
        try:
            described = json.loads(path.read_text())
        except (OSError, ValueError):
            continue
        if isinstance(described, dict):
            for entry in described.get("type_hashes", []):
                out[entry["type_name"]] = entry["hash_string"]
    return out


def test_shared_types_hash_alike_in_both_distributions() -> None:
    """The types both venvs know (several hundred, our interfaces among them) have equal
    hashes; Kilted's extra types are only the keyed test messages."""
    other_python()  # skipped (failed under CI) without the other venv
    mine, theirs = type_hashes(Path(sys.prefix)), type_hashes(VENVS[other_distro()])
    shared = mine.keys() & theirs.keys()
    assert len(shared) > 300 and {"std_msgs/msg/String", "sensor_msgs/msg/Image",
                                  "mult_msgs/srv/MultFloats"} <= shared
    assert sorted(t for t in shared if mine[t] != theirs[t]) == []
    jazzy, kilted = (mine, theirs) if other_distro() == "kilted" else (theirs, mine)
    assert sorted(kilted.keys() - jazzy.keys()) == [
        "test_msgs/msg/ComplexNestedKey", "test_msgs/msg/KeyedLong", "test_msgs/msg/KeyedString",
        "test_msgs/msg/NonKeyedWithNestedKey"]
    assert sorted(jazzy.keys() - kilted.keys()) == []
