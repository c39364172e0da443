"""Every installed ROS interface type round-trips through the bridge's JSON/CBOR conversion.

bridge_server.rclpy_graph.convert over each message, service part and action part found in the
ament index, plus the cached CBOR envelope and the allocator tuning.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cbor2
import pytest
from rosidl_parser import definition as idl

import bridge_server.rclpy_graph.convert as convert_mod
from bridge_server.rclpy_graph.convert import (
    converter_for,
    deserialize,
    encode_publish_cbor,
    serialize,
)
from tests.bridge.convert_support import (
    strict_loads,
    via_cbor,
    via_json,
)

# --------------------------------------------------------------------------------------------
# sweep over every installed interface


def _index_dir() -> Path:
    return Path(sys.prefix) / "share" / "ament_index" / "resource_index" / "rosidl_interfaces"


def _all_classes() -> Iterator[tuple[str, type[Any]]]:
    """Every message class, every service's Request/Response/Event and every action's parts."""
    import importlib

    for entry in sorted(_index_dir().iterdir()):
        pkg = entry.name
        for line in entry.read_text().splitlines():
            kind, _, file = line.strip().partition("/")
            if not file.endswith(".idl"):
                continue
            name = file[: -len(".idl")]
            cls = getattr(importlib.import_module(f"{pkg}.{kind}"), name)
            if kind == "msg":
                yield f"{pkg}/msg/{name}", cls
            elif kind == "srv":
                for part in ("Request", "Response", "Event"):
                    if hasattr(cls, part):
                        yield f"{pkg}/srv/{name}_{part}", getattr(cls, part)
            elif kind == "action":
                impl = cls.Impl
                parts = {
                    "Goal": cls.Goal,
                    "Result": cls.Result,
                    "Feedback": cls.Feedback,
                    "SendGoal_Request": impl.SendGoalService.Request,
                    "SendGoal_Response": impl.SendGoalService.Response,
                    "GetResult_Request": impl.GetResultService.Request,
                    "GetResult_Response": impl.GetResultService.Response,
                    "FeedbackMessage": impl.FeedbackMessage,
                }
                for part, pcls in parts.items():
                    yield f"{pkg}/action/{name}_{part}", pcls


ALL_CLASSES = list(_all_classes())


def _sample(slot_type: Any, owner: type[Any]) -> Any:
    """A non-default value for one rosidl slot type (used to fill messages in the sweep)."""
    t = slot_type
    if isinstance(t, idl.AbstractNestedType):
        if isinstance(t, idl.Array):
            n = t.size
        elif isinstance(t, idl.BoundedSequence):
            n = min(t.maximum_size, 2)
        else:
            n = 2
        return [_sample(t.value_type, owner) for _ in range(n)]
    if isinstance(t, idl.BasicType):
        tn = t.typename
        if tn == "boolean":
            return True
        if tn == "octet":
            return b"\x07"
        if tn in ("float", "double"):
            return 1.5
        if tn in ("char", "wchar"):
            return "c"
        return {"int8": -7, "int16": -300, "int32": -70000, "int64": -(2**40)}.get(tn, 200)
    if isinstance(t, idl.AbstractGenericString):
        bound = getattr(t, "maximum_size", None)
        text = "sé\u2603" if isinstance(t, idl.AbstractWString) else "sé"
        return text[: bound if bound is not None else None]
    if isinstance(t, idl.NamespacedType):
        import importlib

        module = importlib.import_module(".".join(t.namespaces))
        # action parts (Fibonacci_Goal) live only in the owner's private module
        cls = getattr(module, t.name, None) or getattr(sys.modules[owner.__module__], t.name)
        return _filled(cls)
    raise AssertionError(f"unexpected slot type {t!r}")


def _filled(cls: type[Any]) -> Any:
    """An instance of cls with every field set to a non-default value."""
    msg = cls()
    for name, slot in zip(cls.get_fields_and_field_types(), cls.SLOT_TYPES, strict=True):
        setattr(msg, name, _sample(slot, cls))
    return msg


@pytest.mark.parametrize(("name", "cls"), ALL_CLASSES, ids=[n for n, _ in ALL_CLASSES])
def test_sweep_every_installed_type_round_trips(name: str, cls: type[Any]) -> None:
    """Default and filled instances survive JSON and CBOR both ways and stay rclpy-serializable."""
    conv = converter_for(cls)
    assert conv.type_name == name
    for msg in (cls(), _filled(cls)):
        back = via_json(conv, msg)
        assert back == msg
        assert strict_loads(conv.to_json(msg)) == strict_loads(json.dumps(conv.to_obj(msg)))
        assert via_cbor(conv, msg) == msg
        assert deserialize(serialize(back), cls) == msg
        # what a subscription hands the bridge: a message built by rclpy's C layer
        received = deserialize(serialize(msg), cls)
        assert conv.to_json(received) == conv.to_json(msg)
        assert cbor2.dumps(conv.to_cbor_obj(received)) == cbor2.dumps(conv.to_cbor_obj(msg))
    assert conv.from_obj({}) == cls()
    # each field given alone: every other field must come out at its default
    filled_obj = strict_loads(conv.to_json(_filled(cls)))
    for field in conv.fields:
        partial = conv.from_obj({field: filled_obj[field]})
        expected = cls()
        setattr(expected, field, getattr(_filled(cls), field))
        assert partial == expected, field
        assert deserialize(serialize(partial), cls) == expected


def test_sweep_covers_the_required_packages() -> None:
    """The sweep really includes every package the bridge promises to handle."""
    pkgs = {n.split("/")[0] for n, _ in ALL_CLASSES}
    required = {
        "std_msgs",
        "geometry_msgs",
        "sensor_msgs",
        "nav_msgs",
        "diagnostic_msgs",
        "shape_msgs",
        "stereo_msgs",
        "trajectory_msgs",
        "visualization_msgs",
        "actionlib_msgs",
        "builtin_interfaces",
        "std_srvs",
        "test_msgs",
        "action_msgs",
        "unique_identifier_msgs",
        "mult_msgs",
    }
    assert required <= pkgs, required - pkgs
    assert len(ALL_CLASSES) > 200


def test_cbor_envelope_matches_plain_encoding() -> None:
    """The cached CBOR envelope gives exactly the bytes of encoding the whole op dict."""
    from std_msgs.msg import String

    conv = converter_for(String)
    for topic in ("/a", "/b", "/a"):
        msg = String(data=f"on {topic}")
        expected = cbor2.dumps({"op": "publish", "topic": topic, "msg": {"data": f"on {topic}"}})
        assert encode_publish_cbor(topic, msg, conv) == expected


def test_tune_allocator_applies_on_glibc_linux() -> None:
    """tune_allocator reports success where glibc's mallopt exists (this Linux), else False."""
    import platform

    result = convert_mod.tune_allocator()
    assert isinstance(result, bool)
    if sys.platform.startswith("linux") and platform.libc_ver()[0] == "glibc":
        assert result is True
