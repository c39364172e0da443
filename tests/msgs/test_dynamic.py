"""msgs.dynamic: classes built at runtime from definition text behave as generated ones,
cross-checked against rclpy's own classes of a package msgs does not generate (robot_msgs,
a test fixture built into the venv)."""

from __future__ import annotations

import json
import sys

import pytest
from rclpy.serialization import deserialize_message, serialize_message
from robot_msgs.msg import Status as RosStatus
from robot_msgs.srv import SetMode as RosSetMode

from bridge_server.rclpy_graph import convert
from bridge_server.rclpy_graph.introspection import interface_definition
from msgs import cdr, dynamic
from msgs.parser import DefinitionError
from msgs.runtime import Message, Service, UnknownTypeError, ValidationError, lookup
from msgs.sensor_msgs.msg import Image


def _definition(type_name: str) -> str:
    text: str = interface_definition(type_name)["definition"]
    return text


def _status() -> type[Message]:
    cls = dynamic.load("robot_msgs/msg/Status", _definition("robot_msgs/msg/Status"))
    assert isinstance(cls, type) and issubclass(cls, Message)
    return cls


def test_a_robot_type_gets_the_fields_rclpy_has() -> None:
    """The loaded class has rclpy's fields and types, constants, defaults; lookup finds it."""
    status = _status()
    assert status._fields_and_types == RosStatus.get_fields_and_field_types()
    assert (status.MODE_IDLE, status.MODE_DRIVE) == (0, 1)  # type: ignore[attr-defined]
    assert status().label == "robot"  # type: ignore[attr-defined]
    assert lookup("robot_msgs/Status") is status and lookup("robot_msgs/msg/Status") is status
    assert dynamic.load("robot_msgs/msg/Status", "garbage that is not parsed again") is status
    wheel = lookup("robot_msgs/msg/Wheel")
    assert wheel._fields_and_types == {  # type: ignore[union-attr]
        "name": "string", "speed": "double", "ticks": "int32[3]"}


def test_a_robot_type_validates_and_round_trips_cdr_with_rclpy() -> None:
    """Values are checked as for generated types; rclpy's bytes decode here and ours there."""
    status = _status()
    wire = {"header": {"frame_id": "base"}, "mode": 1, "label": "r2",
            "wheels": [{"name": "left", "speed": 0.5, "ticks": [1, 2, 3]}],
            "battery_cells": [3.5, 3.75], "blob": b"\x00\x01\xff",
            "pose": {"position": {"x": 1.0}}}
    msg = status.from_json(wire)
    ros = convert.converter_for(RosStatus).from_obj(json.loads(json.dumps(msg.to_json())), "m")
    assert status.from_json(cdr.decode(serialize_message(ros), status)) == msg
    assert deserialize_message(cdr.encode(msg), RosStatus) == ros
    with pytest.raises(ValidationError, match="label"):
        status.from_json({"label": "x" * 17})  # string<=16
    with pytest.raises(ValidationError, match=r"wheels\[0\]\.ticks"):
        status.from_json({"wheels": [{"ticks": [1, 2]}]})


def test_a_robot_service_loads_with_its_parts() -> None:
    """A .srv with its dependencies: Request and Response as rclpy has them."""
    srv = dynamic.load("robot_msgs/srv/SetMode", _definition("robot_msgs/srv/SetMode"))
    assert isinstance(srv, type) and issubclass(srv, Service)
    assert (srv.Request._fields_and_types
            == RosSetMode.Request.get_fields_and_field_types())
    assert (srv.Response._fields_and_types
            == RosSetMode.Response.get_fields_and_field_types())


def test_known_types_are_not_redefined_and_full_text_loads_back() -> None:
    """A type msgs generates comes back as is; full_text has every dependency once."""
    text = dynamic.full_text("sensor_msgs/msg/Image")
    assert dynamic.load("sensor_msgs/msg/Image", text) is Image
    names = [name for name, _ in dynamic.split("sensor_msgs/msg/Image", text)]
    assert names == ["sensor_msgs/msg/Image", "std_msgs/msg/Header",
                     "builtin_interfaces/msg/Time"]


@pytest.mark.parametrize(("text", "why"), [
    ("int32 x\nNoSuchType y\n", "unknown type dyn_msgs/msg/NoSuchType"),
    ("int32 x\nfloat77 y\n", "float77"),
    ("int32 str\n", "field name 'str' is not supported"),
    ("int32 x\n" + dynamic.DELIMITER + "\nMSG: dyn_msgs/msg/Inner\nint32 bad line here\n",
     "Inner"),
])
def test_malformed_definitions_name_the_type_and_line(text: str, why: str) -> None:
    """Every broken text raises DefinitionError naming the cause; nothing is registered."""
    with pytest.raises(DefinitionError, match=why):
        dynamic.load("dyn_msgs/msg/Broken", text)
    with pytest.raises(UnknownTypeError):
        lookup("dyn_msgs/msg/Broken")


def test_a_new_type_in_a_generated_package_is_refused_clearly() -> None:
    """msgs' own packages cannot take runtime types: the error says to regenerate."""
    with pytest.raises(DefinitionError, match="regenerate msgs"):
        dynamic.load("std_msgs/msg/Novel", "int32 x\n")


def test_two_stores_keep_two_layouts_of_one_name_nested_types_too() -> None:
    """Two stores define the same names differently: each class (and its nested type, found
    through its own store) encodes, decodes CDR and checks in its own layout; the
    process-wide lookup knows neither; a closed store's modules are gone."""
    inner = f"{dynamic.DELIMITER}\nMSG: two_msgs/msg/Inner\n"
    one, two = dynamic.TypeStore("one"), dynamic.TypeStore("two")
    one.load("two_msgs/msg/Outer", "Inner inner\n" + inner + "int32 x\n")
    two.load("two_msgs/msg/Outer", "Inner inner\n" + inner + "string name\n")
    a, b = one.lookup_message("two_msgs/msg/Outer"), two.lookup_message("two_msgs/Outer")
    assert one.lookup_message("two_msgs/Inner")._fields_and_types == {"x": "int32"}
    assert two.lookup_message("two_msgs/msg/Inner")._fields_and_types == {"name": "string"}
    msg_a = a.from_json({"inner": {"x": 5}})
    msg_b = b.from_json({"inner": {"name": "five"}})
    assert a.from_json(cdr.decode(cdr.encode(msg_a), a)) == msg_a
    assert b.from_json(cdr.decode(cdr.encode(msg_b), b)) == msg_b
    with pytest.raises(ValidationError, match=r"inner\.name"):
        a.from_json({"inner": {"name": "five"}})
    assert dynamic.full_text(b).endswith("string name\n") and len(one) == len(two) == 2
    with pytest.raises(UnknownTypeError):
        lookup("two_msgs/msg/Outer")
    module = a.__module__
    assert module in sys.modules
    one.close()
    assert module not in sys.modules and b.__module__ in sys.modules
    with pytest.raises(DefinitionError, match="released"):
        one.load("two_msgs/msg/Other", "int32 y\n")


def test_a_store_builds_a_text_once_and_refuses_what_is_over_its_limits(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The same (name, text) again is neither split nor parsed; a definition over the size
    or type-count limit raises LimitError naming the limit, and defines nothing."""
    store = dynamic.TypeStore("limited", max_types=2, max_definition_bytes=120)
    first = store.load("lim_msgs/msg/A", "int32 a\n")
    splits: list[str] = []
    real_split = dynamic.split

    def counted(name: str, text: str) -> list[tuple[str, str]]:
        splits.append(name)
        return real_split(name, text)

    monkeypatch.setattr(dynamic, "split", counted)
    assert store.load("lim_msgs/msg/A", "int32 a\n") is first and splits == []
    with pytest.raises(dynamic.LimitError, match="max_definition_bytes") as big:
        store.load("lim_msgs/msg/B", "int32 b\n" + "# pad\n" * 20)
    assert (big.value.allowed, big.value.got) == (120, 128)
    with pytest.raises(dynamic.LimitError, match="max_types"):
        store.load("lim_msgs/msg/C", "D d\n" + dynamic.DELIMITER + "\nMSG: lim_msgs/msg/D\n"
                   "int32 d\n")
    assert len(store) == 1 and splits == ["lim_msgs/msg/C"]  # B was refused unsplit
