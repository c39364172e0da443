"""rosbag2 recordings for the tests, in rosbag2's own layouts: ``rosbags`` writes the
storage files (SQLite3 ``.db3`` or MCAP, as rosbag2's storage plugins lay them out), and a
recording split into several files gets its ``metadata.yaml`` from :func:`metadata_yaml`,
written as rosbag2 writes it (``rosbag2_storage``'s ``yaml.hpp`` converters, version 9,
as yaml-cpp emits them: rosbag2 itself is not on the package index)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

#: A message as the tests hand it over: (topic, type, log time in ns, CDR bytes).
Entry = tuple[str, str, int, bytes]

_INFINITE = {"sec": 9223372036, "nsec": 854775807}  # RMW_DURATION_INFINITE, as rosbag2 dumps it


def qos_profile(durability: str) -> dict[str, Any]:
    """One offered QoS profile as rosbag2 9+ writes it (a publisher's, keep last 10)."""
    return {"history": "keep_last", "depth": 10, "reliability": "reliable",
            "durability": durability, "deadline": _INFINITE, "lifespan": _INFINITE,
            "liveliness": "automatic", "liveliness_lease_duration": _INFINITE,
            "avoid_ros_namespace_conventions": False}


def write_storage(folder: Path, entries: list[Entry], storage: str, *,
                  latched: frozenset[str] = frozenset(), compression: str = "") -> Path:
    """A one-file rosbag2 directory of ``entries`` written by rosbags (its metadata.yaml
    too): ``storage`` is ``sqlite3`` or ``mcap``; ``compression`` rosbag2's zstd mode,
    ``message`` or ``file`` (none by default)."""
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability
    from rosbags.interfaces import QosTime as T

    store = get_typestore(Stores.ROS2_JAZZY)
    inf = T(**_INFINITE)
    writer = Writer(folder, version=9, storage_plugin=StoragePlugin[storage.upper()])
    if compression:
        writer.set_compression(CompressionMode[compression.upper()], CompressionFormat.ZSTD)
    conns: dict[str, Any] = {}
    with writer:
        for topic, type_name, stamp, data in entries:
            if topic not in conns:
                qos = Qos(QosHistory.KEEP_LAST, 10, QosReliability.RELIABLE,
                          QosDurability.TRANSIENT_LOCAL if topic in latched
                          else QosDurability.VOLATILE, inf, inf, QosLiveliness.AUTOMATIC, inf,
                          False)
                conns[topic] = writer.add_connection(topic, type_name, typestore=store,
                                                     offered_qos_profiles=[qos])
            writer.write(conns[topic], stamp, data)
    return folder


def write_split(folder: Path, entries: list[Entry], storage: str, parts: int,
                version: int = 9) -> Path:
    """A rosbag2 directory of ``entries`` split by time into ``parts`` files named as
    rosbag2 names them (``<folder>_0.db3``...), with rosbag2's metadata.yaml (``version``
    9, as Jazzy writes it, or 8, as Iron did)."""
    folder.mkdir()
    suffix = ".db3" if storage == "sqlite3" else ".mcap"
    files: list[dict[str, Any]] = []
    per = -(-len(entries) // parts)
    for i in range(parts):
        part = entries[i * per:(i + 1) * per]
        scratch = folder.parent / f"{folder.name}.part{i}"
        write_storage(scratch, part, storage)
        name = f"{folder.name}_{i}{suffix}"
        shutil.move(scratch / f"{scratch.name}{suffix}", folder / name)
        shutil.rmtree(scratch)
        files.append({"path": name, "start": part[0][2], "duration": part[-1][2] - part[0][2],
                      "count": len(part)})
    topics: dict[str, list[Any]] = {}
    for topic, type_name, _t, _d in entries:
        topics.setdefault(topic, [type_name, 0])[1] += 1
    (folder / "metadata.yaml").write_text(metadata_yaml(storage, entries, topics, files,
                                                        version))
    return folder


def metadata_yaml(storage: str, entries: list[Entry], topics: dict[str, list[Any]],
                  files: list[dict[str, Any]], version: int = 9) -> str:
    """``metadata.yaml`` as rosbag2 writes it: the keys in ``convert<BagMetadata>::encode``'s
    order, 2-space blocks as yaml-cpp emits them; QoS profiles a YAML list (version 9,
    Jazzy on), or one double-quoted string of YAML with the policies as numbers (8)."""
    start = min(t for _, _, t, _ in entries)
    lines = ["rosbag2_bagfile_information:", f"  version: {version}",
             f"  storage_identifier: {storage}", "  duration:",
             f"    nanoseconds: {max(t for _, _, t, _ in entries) - start}",
             "  starting_time:", f"    nanoseconds_since_epoch: {start}",
             f"  message_count: {len(entries)}", "  topics_with_message_count:"]
    for name, (type_name, count) in topics.items():
        lines += ["    - topic_metadata:", f"        name: {name}", f"        type: {type_name}",
                  "        serialization_format: cdr"]
        qos = _qos_lines(version)
        if version >= 9:
            lines += ["        offered_qos_profiles:", *(f"          {q}" for q in qos)]
        else:
            lines.append(f"        offered_qos_profiles: {json.dumps(chr(10).join(qos))}")
        lines += ["        type_description_hash: RIHS01_" + "0" * 64,
                  f"      message_count: {count}"]
    lines += ['  compression_format: ""', '  compression_mode: ""', "  relative_file_paths:"]
    lines += [f"    - {f['path']}" for f in files]
    lines.append("  files:")
    for f in files:
        lines += [f"    - path: {f['path']}", "      starting_time:",
                  f"        nanoseconds_since_epoch: {f['start']}", "      duration:",
                  f"        nanoseconds: {f['duration']}", f"      message_count: {f['count']}"]
    lines += ["  custom_data: ~", f"  ros_distro: {'jazzy' if version >= 9 else 'iron'}"]
    return "\n".join(lines) + "\n"


_V8_NUMBERS = {"keep_last": 1, "reliable": 1, "volatile": 2, "automatic": 1}
"""Before version 9, rosbag2 wrote the policies as rmw's enum values."""


def _qos_lines(version: int) -> list[str]:
    """One volatile profile as a block YAML list, as yaml-cpp emits it (unindented)."""
    lines, lead = [], "- "
    for key, value in qos_profile("volatile").items():
        if isinstance(value, dict):
            lines.append(f"{lead}{key}:")
            lines += [f"    {k}: {v}" for k, v in value.items()]
        else:
            shown = _V8_NUMBERS.get(value, value) if version < 9 else value
            lines.append(f"{lead}{key}: {str(shown).lower()}")
        lead = "  "
    return lines
