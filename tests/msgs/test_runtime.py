"""Tests of msgs.runtime: JSON conversion, validation and lookup of generated types."""

from __future__ import annotations

import array
import base64
import dataclasses
import json
import math
import subprocess
import sys
from typing import Any

import pytest

from msgs.builtin_interfaces.msg import Duration, Time
from msgs.geometry_msgs.msg import Point, Pose, PoseStamped, Twist
from msgs.mult_msgs.srv import MultFloats, MultFloats_Request, MultFloats_Response
from msgs.runtime import (
    Action,
    Message,
    Service,
    UnknownTypeError,
    ValidationError,
    available_packages,
    available_types,
    lookup,
    lookup_action,
    lookup_message,
    lookup_service,
)
from msgs.sensor_msgs.msg import Image, JointState, PointCloud2
from msgs.std_msgs.msg import ColorRGBA, Header, Int16, String, UInt8MultiArray
from msgs.test_msgs.action import Fibonacci, Fibonacci_Feedback, Fibonacci_Goal
from msgs.test_msgs.msg import Arrays, BasicTypes, BoundedSequences, Constants, Defaults, Strings


def test_default_construction_and_keywords() -> None:
    """Messages build from keywords with defaults; positional arguments are refused."""
    assert String().data == ""
    assert String(data="hi").data == "hi"
    assert Pose().orientation.w == 1.0
    assert Defaults().int8_value == -50 and Defaults().bool_value is True
    assert Arrays().float64_values == [0.0, 0.0, 0.0]
    assert Arrays().uint8_values == b"\x00\x00\x00"
    assert Arrays().uint8_values_default == b"\x00\x01\xff"
    assert Arrays().byte_values_default == [0, 1, 255]
    assert len(Arrays().basic_types_values) == 3
    with pytest.raises(TypeError):
        String("positional")  # type: ignore[call-arg]


def test_instances_are_mutable_and_defaults_not_shared() -> None:
    """Fields can be reassigned and mutable defaults are per instance."""
    a, b = JointState(), JointState()
    a.name.append("j1")
    a.header.frame_id = "base"
    assert b.name == [] and b.header.frame_id == ""
    with pytest.raises(AttributeError):
        a.nonexistent = 1  # type: ignore[attr-defined]


def test_type_names_and_definitions() -> None:
    """_type uses pkg/msg|srv|action/Name spellings and _definition holds the source."""
    assert String._type == "std_msgs/msg/String"
    assert MultFloats._type == "mult_msgs/srv/MultFloats"
    assert MultFloats.Request is MultFloats_Request
    assert MultFloats.Response._type == "mult_msgs/srv/MultFloats_Response"
    assert Fibonacci._type == "test_msgs/action/Fibonacci"
    assert Fibonacci.Goal is Fibonacci_Goal
    assert Fibonacci.Result._type == "test_msgs/action/Fibonacci_Result"
    assert Fibonacci.Feedback is Fibonacci_Feedback
    assert "string data" in String._definition
    assert "---" in MultFloats._definition and "---" not in MultFloats.Request._definition


def test_fields_and_types_convention() -> None:
    """_fields_and_types uses rclpy's spelling for each kind of type."""
    assert Header._fields_and_types == {"stamp": "builtin_interfaces/Time", "frame_id": "string"}
    assert Int16.get_fields_and_field_types() == {"data": "int16"}
    assert BoundedSequences._fields_and_types["int32_values"] == "sequence<int32, 3>"
    assert Arrays._fields_and_types["float32_values"] == "float[3]"
    assert Strings._fields_and_types["bounded_string_value"] == "string<22>"
    assert JointState._fields_and_types["position"] == "sequence<double>"


def test_constants_are_class_attributes() -> None:
    """Constants are plain class attributes and not dataclass fields."""
    assert Constants.INT8_CONST == -50 and Constants.BOOL_CONST is True
    assert Constants.FLOAT64_CONST == 1.125
    assert [f.name for f in dataclasses.fields(Constants)] == []


def test_services_and_actions_are_not_instantiable() -> None:
    """Service and action namespaces refuse instantiation with a pointer to their parts."""
    with pytest.raises(TypeError, match="Request"):
        MultFloats()
    with pytest.raises(TypeError, match="Goal"):
        Fibonacci()
    assert issubclass(MultFloats, Service) and issubclass(Fibonacci, Action)


def test_to_json_basic_and_nested() -> None:
    """to_json gives plain dicts, nested messages as dicts and Time as sec/nanosec."""
    msg = PoseStamped(header=Header(stamp=Time(sec=5, nanosec=7), frame_id="map"))
    msg.pose.position.x = 1.5
    assert msg.to_json() == {
        "header": {"stamp": {"sec": 5, "nanosec": 7}, "frame_id": "map"},
        "pose": {
            "position": {"x": 1.5, "y": 0.0, "z": 0.0},
            "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
        },
    }
    assert json.loads(json.dumps(msg.to_json())) == msg.to_json()


def test_to_json_base64_for_uint8_and_char_arrays() -> None:
    """uint8[] and char[] (any array kind) become base64; byte[] stays a list of ints."""
    out = Arrays(uint8_values=b"\x01\x02\x03", char_values=b"abc").to_json()
    assert out["uint8_values"] == base64.b64encode(b"\x01\x02\x03").decode()
    assert out["char_values"] == "YWJj"
    assert out["byte_values"] == [0, 0, 0]
    assert Image(data=bytes(range(256))).to_json()["data"] == base64.b64encode(
        bytes(range(256))
    ).decode("ascii")


def test_to_json_nan_and_inf_become_none() -> None:
    """Non-finite floats become None in scalars and arrays; the output is strict JSON."""
    msg = JointState(position=[1.0, math.nan, math.inf, -math.inf])
    out = msg.to_json()
    assert out["position"] == [1.0, None, None, None]
    assert Point(x=math.nan, y=-math.inf).to_json() == {"x": None, "y": None, "z": 0.0}
    json.dumps(out, allow_nan=False)


def test_to_json_returns_fresh_lists() -> None:
    """Mutating to_json output does not change the message."""
    msg = JointState(name=["a"])
    msg.to_json()["name"].append("b")
    assert msg.name == ["a"]


def test_round_trip_of_every_test_msgs_type() -> None:
    """from_json(to_json(m)) == m for default instances of rich test types."""
    for cls in (Arrays, BasicTypes, BoundedSequences, Defaults, Strings, PointCloud2, Image):
        msg = cls()
        assert cls.from_json(json.loads(json.dumps(msg.to_json()))) == msg


def test_round_trip_with_values() -> None:
    """A message with bytes, lists, nested arrays and NaN survives JSON both ways."""
    msg = BoundedSequences(
        uint8_values=b"\xff\x00",
        float32_values=[1.5],
        string_values=["a", "b"],
        basic_types_values=[BasicTypes(int64_value=-(2**63), uint64_value=2**64 - 1)],
    )
    back = BoundedSequences.from_json(json.loads(json.dumps(msg.to_json())))
    assert back == msg
    js = JointState.from_json(json.loads(json.dumps(JointState(effort=[math.nan]).to_json())))
    assert math.isnan(js.effort[0])


def test_from_json_missing_fields_keep_defaults() -> None:
    """Fields absent from the input keep their defaults."""
    msg = Defaults.from_json({"int32_value": 1})
    assert msg.int32_value == 1 and msg.int8_value == -50 and msg.float64_value == 1.125
    assert Pose.from_json({}).orientation.w == 1.0


def test_from_json_uint8_array_forms() -> None:
    """uint8[] accepts base64 text, bytes, bytearray, memoryview and a list of ints."""
    for form in ("AQID", b"\x01\x02\x03", bytearray(b"\x01\x02\x03"), memoryview(b"\x01\x02\x03"),
                 [1, 2, 3], (1, 2, 3)):  # fmt: skip
        assert UInt8MultiArray.from_json({"data": form}).data == b"\x01\x02\x03"


def test_from_json_numeric_array_forms() -> None:
    """Numeric arrays accept list, tuple, array.array and memoryview (CBOR typed arrays)."""
    expected = [1.0, 2.5]
    for form in (
        [1.0, 2.5],
        (1, 2.5),
        array.array("d", expected),
        memoryview(array.array("d", expected)),
    ):
        msg = JointState.from_json({"position": form})
        assert msg.position == expected and type(msg.position) is list


def test_from_json_byte_array_accepts_bytes_and_base64() -> None:
    """byte[] (octet) accepts a list of ints, bytes (CBOR) or base64 text."""
    for form in ([0, 1, 255], b"\x00\x01\xff", "AAH/"):
        assert Arrays.from_json({"byte_values": form}).byte_values == [0, 1, 255]


def test_from_json_none_float_is_nan() -> None:
    """None for a float field (how NaN travels in JSON) gives NaN."""
    assert math.isnan(Point.from_json({"x": None}).x)


def test_from_json_accepts_message_instances() -> None:
    """A nested field may be given an instance of its class."""
    msg = PoseStamped.from_json({"pose": Pose(position=Point(x=2.0))})
    assert msg.pose.position.x == 2.0


def test_from_json_time_and_duration() -> None:
    """builtin Time and Duration take {sec, nanosec}."""
    assert Header.from_json({"stamp": {"sec": 1, "nanosec": 2}}).stamp == Time(sec=1, nanosec=2)
    assert Duration.from_json({"sec": -1, "nanosec": 5}) == Duration(sec=-1, nanosec=5)


def _error(cls: type[Message], data: Any) -> ValidationError:
    with pytest.raises(ValidationError) as info:
        cls.from_json(data)
    return info.value


def test_error_wrong_kind_names_full_path_and_type() -> None:
    """A wrong kind of value names the full field path and the expected type."""
    err = _error(PoseStamped, {"pose": {"position": {"x": "abc"}}})
    assert err.path == "pose.position.x" and err.expected == "float64"
    assert str(err).startswith("pose.position.x: expected float64, got str")
    assert isinstance(err, ValueError)


def test_error_unknown_field_names_path() -> None:
    """An unknown field is an error naming its path and the real fields."""
    err = _error(PoseStamped, {"pose": {"positon": {}}})
    assert err.path == "pose.positon"
    assert "position, orientation" in str(err)


@pytest.mark.parametrize(
    ("cls", "data", "path", "expected"),
    [
        (Int16, {"data": 40000}, "data", "int16"),
        (Int16, {"data": True}, "data", "int16"),
        (Int16, {"data": 1.5}, "data", "int16"),
        (BasicTypes, {"uint8_value": -1}, "uint8_value", "uint8"),
        (BasicTypes, {"uint64_value": 2**64}, "uint64_value", "uint64"),
        (BasicTypes, {"byte_value": 256}, "byte_value", "byte"),
        (BasicTypes, {"bool_value": 1}, "bool_value", "bool"),
        (BasicTypes, {"float32_value": 1e39}, "float32_value", "float32"),
        (BasicTypes, {"float64_value": "1"}, "float64_value", "float64"),
        (String, {"data": 5}, "data", "string"),
        (Strings, {"bounded_string_value": "x" * 23}, "bounded_string_value", "string<=22"),
        (Arrays, {"int32_values": [1, 2]}, "int32_values", "int32[3]"),
        (Arrays, {"uint8_values": "AAAAAA=="}, "uint8_values", "uint8[3]"),
        (BoundedSequences, {"int32_values": [1, 2, 3, 4]}, "int32_values", "int32[<=3]"),
        (BoundedSequences, {"int32_values": [1, "x"]}, "int32_values[1]", "int32"),
        (UInt8MultiArray, {"data": "not base64!"}, "data", "uint8[]"),
        (UInt8MultiArray, {"data": [1, 256]}, "data[1]", "uint8"),
        (UInt8MultiArray, {"data": 5}, "data", "uint8[]"),
        (UInt8MultiArray, {"data": [1, True]}, "data[1]", "uint8"),
        (UInt8MultiArray, {"data": array.array("d", [1.5])}, "data[0]", "uint8"),
        (UInt8MultiArray, {"data": memoryview(array.array("d", [1.0]))}, "data[0]", "uint8"),
        (JointState, {"position": [1.0, "x"]}, "position[1]", "float64"),
        (JointState, {"position": [1.0, True]}, "position[1]", "float64"),
        (BoundedSequences, {"float32_values": [1.0, 1e39]}, "float32_values[1]", "float32"),
        (BoundedSequences, {"bool_values": [True, 0]}, "bool_values[1]", "bool"),
        (BoundedSequences, {"int8_values": [1, -129]}, "int8_values[1]", "int8"),
        (BoundedSequences, {"string_values": ["a", None]}, "string_values[1]", "string"),
        (Arrays, {"byte_values": [0, 1, 256]}, "byte_values[2]", "byte"),
        (Arrays, {"byte_values": "AAAAAA=="}, "byte_values", "byte[3]"),
        (JointState, {"name": "abc"}, "name", "string[]"),
        (JointState, {"header": 5}, "header", "std_msgs/Header object"),
        (
            BoundedSequences,
            {"basic_types_values": [{}, {"int8_value": 300}]},
            "basic_types_values[1].int8_value",
            "int8",
        ),
        (Twist, {"linear": {"x": [1]}}, "linear.x", "float64"),
    ],
)
def test_validation_errors(
    cls: type[Message], data: dict[str, Any], path: str, expected: str
) -> None:
    """Each bad value raises ValidationError naming the path and the expected type."""
    err = _error(cls, data)
    assert (err.path, err.expected) == (path, expected)
    assert str(err).startswith(f"{path}: expected {expected}")


def test_from_json_rejects_non_mapping() -> None:
    """from_json of something other than a mapping names the message type."""
    err = _error(String, ["data"])
    assert "std_msgs/msg/String" in str(err)


def test_integral_float_is_accepted_for_integers() -> None:
    """A JSON number like 3.0 is accepted for an integer field."""
    assert Int16.from_json({"data": 3.0}).data == 3


def test_validate_checks_python_side_values() -> None:
    """validate() checks kinds, ranges, lengths and nested messages of an instance whose
    fields were reassigned after it was built."""
    Arrays().validate()
    PoseStamped().validate()
    msg = PoseStamped()
    msg.pose.position.x = "1"  # type: ignore[assignment]
    with pytest.raises(ValidationError, match=r"^pose\.position\.x: expected float64"):
        msg.validate()
    cases: list[tuple[Any, str, Any, str]] = [
        (Arrays(), "int32_values", [1], "int32_values"),
        (UInt8MultiArray(), "data", "AQID", "data: expected uint8"),
        (PoseStamped(), "pose", Point(), "pose: expected geometry_msgs/Pose"),
        (Int16(), "data", 2**15, "data: expected int16, 32768 is out of range"),
        (JointState(), "position", (1.0,), r"^position: expected float64\[\] \(a list\)"),
        (BoundedSequences(), "basic_types_values", [BasicTypes(), BasicTypes()],
         r"^basic_types_values\[1\]\.int8_value: "),
    ]
    for target, field, value, error in cases:
        setattr(target, field, value)
        if field == "basic_types_values":
            value[1].int8_value = 999
        with pytest.raises(ValidationError, match=error):
            target.validate()


@pytest.mark.parametrize(("build", "error"), [
    (lambda: UInt8MultiArray(data="AQID"), r"^data: expected uint8\[\], got str 'AQID' "  # type: ignore[arg-type]
                                          r"\(building std_msgs/msg/UInt8MultiArray\)$"),
    (lambda: BasicTypes(uint8_value="fast"), r"^uint8_value: expected uint8, got str 'fast' "  # type: ignore[arg-type]
                                             r"\(building test_msgs/msg/BasicTypes\)$"),
    (lambda: Int16(data=2**15), "data: expected int16, 32768 is out of range"),
    (lambda: Arrays(int32_values=[1]), r"^int32_values: expected int32\[3\], got 1 elements"),
    (lambda: PoseStamped(pose=Point()), "pose: expected geometry_msgs/Pose instance"),  # type: ignore[arg-type]
    (lambda: JointState(position=(1.0,)), r"^position: expected float64\[\] \(a list\)"),  # type: ignore[arg-type]
    (lambda: JointState(name=["a", 2]), r"^name\[1\]: expected string, got int 2"),  # type: ignore[list-item]
    (lambda: BoundedSequences(basic_types_values=[BasicTypes()] * 4), "basic_types_values"),
    (lambda: BasicTypes(float32_value=1e39), "out of the float32 range"),
    (lambda: BasicTypes(bool_value=1), "bool_value: expected bool"),  # type: ignore[arg-type]
])
def test_a_message_is_checked_when_it_is_built(build: Any, error: str) -> None:
    """A field of the wrong kind, range or length raises at construction, naming the field,
    the expected type and the message type (as an unknown field does), not at publish."""
    with pytest.raises(ValidationError, match=error):
        build()


def test_construction_keeps_what_it_accepts() -> None:
    """Values that fit pass unchanged: ints for floats, float32 infinities, bytes-likes, nested
    instances (checked when they were built), ints that a float64 array may hold."""
    assert BasicTypes(float64_value=2).float64_value == 2
    assert BasicTypes(float32_value=math.inf).float32_value == math.inf
    assert UInt8MultiArray(data=bytearray(b"ab")).data == bytearray(b"ab")  # type: ignore[arg-type]
    pose = PoseStamped(pose=PoseStamped().pose)
    assert pose.pose.position.x == 0.0
    assert JointState(position=[1, 2.5]).position == [1, 2.5]


def test_lookup_accepts_both_spellings() -> None:
    """lookup resolves pkg/Name and pkg/kind/Name for messages, services and actions."""
    assert lookup("std_msgs/String") is String
    assert lookup("std_msgs/msg/String") is String
    assert lookup("mult_msgs/MultFloats") is MultFloats
    assert lookup("mult_msgs/srv/MultFloats") is MultFloats
    assert lookup("test_msgs/Fibonacci") is Fibonacci
    assert lookup("test_msgs/action/Fibonacci") is Fibonacci
    assert lookup("mult_msgs/srv/MultFloats_Response") is MultFloats_Response
    assert lookup("test_msgs/BasicTypes") is BasicTypes
    assert lookup_message("std_msgs/ColorRGBA") is ColorRGBA
    assert lookup_service("mult_msgs/MultFloats") is MultFloats
    assert lookup_service("test_msgs/BasicTypes")._type == "test_msgs/srv/BasicTypes"
    assert lookup_action("test_msgs/Fibonacci") is Fibonacci


@pytest.mark.parametrize(
    ("name", "reason"),
    [
        ("std_msgs/Nope", "no type 'Nope' in std_msgs"),
        ("std_msgs/srv/String", "no type 'String' in std_msgs/srv"),
        ("no_such_pkg/msg/Thing", "no type 'Thing'"),
        ("std_msgs", "expected 'package/Name'"),
        ("std_msgs/msg/string", "did you mean 'std_msgs/msg/String'?"),
        ("std_msgs/foo/String", "expected 'package/Name'"),
        ("../x/Y", "expected 'package/Name'"),
        ("runtime/Message", "no generated package 'runtime'"),
        ("std_msgs/Message", "no type 'Message'"),
    ],
)
def test_lookup_unknown_types(name: str, reason: str) -> None:
    """Unknown or malformed names raise UnknownTypeError (a LookupError) saying why."""
    with pytest.raises(UnknownTypeError) as info:
        lookup(name)
    assert isinstance(info.value, LookupError)
    assert reason in str(info.value) and name in str(info.value)


def test_lookup_kind_mismatch() -> None:
    """The typed lookups refuse a type of another kind."""
    with pytest.raises(UnknownTypeError, match="not a message type"):
        lookup_message("mult_msgs/srv/MultFloats")
    with pytest.raises(UnknownTypeError, match="not an action type"):
        lookup_action("std_msgs/msg/String")
    with pytest.raises(UnknownTypeError, match="not a service type"):
        lookup_service("std_msgs/msg/String")


def test_generated_packages_import_lazily() -> None:
    """Importing msgs.runtime or one package imports no other generated package."""
    code = (
        "import sys, msgs.runtime, msgs.std_msgs.msg\n"
        "loaded = sorted(m for m in sys.modules if m.startswith('msgs.') and m.count('.') == 2)\n"
        "print(loaded)\n"
        "assert not any(m.startswith(('rclpy', 'rosidl')) for m in sys.modules)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=60
    )
    assert out.stdout.strip() == "['msgs.builtin_interfaces.msg', 'msgs.std_msgs.msg']"


def test_available_packages_and_types() -> None:
    """The listing names every generated package and type, each resolvable by lookup."""
    packages = available_packages()
    assert {"std_msgs", "mult_msgs", "test_msgs", "builtin_interfaces"} <= set(packages)
    assert "interfaces" not in packages and "runtime" not in packages
    types = available_types("test_msgs")
    assert "test_msgs/action/Fibonacci" in types and "test_msgs/srv/BasicTypes" in types
    assert "test_msgs/msg/BasicTypes" in types
    assert not any(t.endswith(("_Request", "_Goal")) for t in types)
    assert all(lookup(t)._type == t for t in types)
    assert available_types("mult_msgs") == [
        "mult_msgs/action/IntegrateImu", "mult_msgs/srv/MultFloats"
    ]
    assert len(available_types()) > 150 and "sensor_msgs/msg/Image" in available_types()
