"""Tests of the pure-Python .msg/.srv/.action parser."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from msgs.parser import (
    ActionSpec,
    DefinitionError,
    MessageSpec,
    ServiceSpec,
    TypeRef,
    parse_action,
    parse_file,
    parse_message,
    parse_service,
)


def _msg(text: str, package: str = "pkg", name: str = "T") -> MessageSpec:
    return parse_message(text, package, name, file="T.msg")


def _field_types(spec: MessageSpec) -> dict[str, str]:
    return {f.name: f.type.idl_name() for f in spec.fields}


def test_every_primitive_type() -> None:
    """Every primitive maps to rclpy's type spelling and has no default."""
    names = [
        "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
        "int32", "uint32", "int64", "uint64", "string", "wstring",
    ]  # fmt: skip
    spec = _msg("".join(f"{n} f_{n}\n" for n in names))
    assert _field_types(spec) == {
        "f_bool": "boolean",
        "f_byte": "octet",
        "f_char": "uint8",
        "f_float32": "float",
        "f_float64": "double",
        "f_int8": "int8",
        "f_uint8": "uint8",
        "f_int16": "int16",
        "f_uint16": "uint16",
        "f_int32": "int32",
        "f_uint32": "uint32",
        "f_int64": "int64",
        "f_uint64": "uint64",
        "f_string": "string",
        "f_wstring": "wstring",
    }
    assert all(f.default is None and f.type.is_primitive for f in spec.fields)


def test_arrays_and_bounds() -> None:
    """Fixed arrays, bounded and unbounded sequences and bounded strings parse."""
    spec = _msg(
        "int32[3] a\nfloat64[<=5] b\nuint8[] c\nstring<=10 d\nstring<=4[<=2] e\nwstring<=3[2] f\n"
    )
    assert _field_types(spec) == {
        "a": "int32[3]",
        "b": "sequence<double, 5>",
        "c": "sequence<uint8>",
        "d": "string<10>",
        "e": "sequence<string<4>, 2>",
        "f": "wstring<3>[2]",
    }
    a, b, c, d, e, _ = spec.fields
    assert (a.type.array, a.type.array_size) == ("fixed", 3)
    assert (b.type.array, b.type.array_size) == ("bounded", 5)
    assert (c.type.array, c.type.array_size) == ("unbounded", None)
    assert d.type.string_bound == 10 and not d.type.is_array
    assert str(e.type) == "string<=4[<=2]"


def test_nested_types_resolve_packages() -> None:
    """Unqualified names resolve to the own package; pkg/Name and pkg/msg/Name keep theirs."""
    spec = _msg(
        "Header a\nstd_msgs/Header b\nbuiltin_interfaces/Time c\n"
        "geometry_msgs/msg/Point[] d\nOther[<=2] e\n",
        package="my_pkg",
    )
    assert _field_types(spec) == {
        "a": "my_pkg/Header",
        "b": "std_msgs/Header",
        "c": "builtin_interfaces/Time",
        "d": "sequence<geometry_msgs/Point>",
        "e": "sequence<my_pkg/Other, 2>",
    }
    assert spec.fields[2].type.message_type == "builtin_interfaces/msg/Time"
    assert not spec.fields[0].type.is_primitive


def test_scalar_defaults() -> None:
    """Scalar defaults parse to Python values of the field's kind."""
    spec = _msg(
        "bool a true\nbool b False\nint8 c -128\nuint64 d 18446744073709551615\n"
        "float32 e 1.125\nfloat64 f -3\nbyte g 255\nchar h 100\nint32 i 0x10\n"
        "float64 j nan\nfloat64 k -inf\n"
    )
    values = {f.name: f.default for f in spec.fields}
    assert values["a"] is True and values["b"] is False
    assert values["c"] == -128 and values["d"] == 2**64 - 1
    assert values["e"] == 1.125 and values["f"] == -3.0 and isinstance(values["f"], float)
    assert values["g"] == 255 and values["h"] == 100 and values["i"] == 16
    assert isinstance(values["j"], float) and math.isnan(values["j"])
    assert values["k"] == -math.inf


def test_string_defaults_quoted_bare_and_escaped() -> None:
    """String defaults may be double-quoted, single-quoted, escaped or bare."""
    spec = _msg(
        'string a "Hello world!"\n'
        "string b 'Hello\"world!'\n"
        "string c 'Hello\\'world!'\n"
        'string d "Hello\\"world!"\n'
        "string e bare text\n"
        'string f "has # inside" # and a comment\n'
        'string<=5 g "abc"\n'
    )
    values = {f.name: f.default for f in spec.fields}
    assert values == {
        "a": "Hello world!",
        "b": 'Hello"world!',
        "c": "Hello'world!",
        "d": 'Hello"world!',
        "e": "bare text",
        "f": "has # inside",
        "g": "abc",
    }


def test_array_defaults() -> None:
    """Array defaults parse element-wise, including quoted strings with commas."""
    spec = _msg(
        "int32[3] a [1, 2, 3]\nfloat64[] b [1.5, -2]\nbool[<=3] c [true, false]\n"
        "string[2] d [\"a,b\", 'c']\nuint8[] e []\n"
    )
    values = {f.name: f.default for f in spec.fields}
    assert values == {
        "a": (1, 2, 3),
        "b": (1.5, -2.0),
        "c": (True, False),
        "d": ("a,b", "c"),
        "e": (),
    }


def test_constants() -> None:
    """Constants of every primitive kind parse, with or without spaces around '='."""
    spec = _msg(
        'int32 X=5\nstring S="x # y"\nstring BARE=hello  # comment\nfloat64 PI = 3.14\n'
        "bool FLAG=true\nuint8 MAX=255\nint32 value\n"
    )
    assert {c.name: c.value for c in spec.constants} == {
        "X": 5,
        "S": "x # y",
        "BARE": "hello",
        "PI": 3.14,
        "FLAG": True,
        "MAX": 255,
    }
    assert [f.name for f in spec.fields] == ["value"]
    assert spec.constants[0].type == TypeRef("int32")


def test_comments_and_blank_lines_are_ignored() -> None:
    """Comment-only lines, trailing comments and blank lines add nothing; source is kept."""
    text = "# header comment\n\n  # indented\nint32 a  # trailing\n\t\nint32 b 7 # c\n"
    spec = _msg(text)
    assert [(f.name, f.default, f.line) for f in spec.fields] == [("a", None, 4), ("b", 7, 6)]
    assert spec.source == text


def test_service_parts_and_lines() -> None:
    """A service splits at '---' into Request and Response with correct line numbers."""
    spec = parse_service("# c\nfloat64 x\nfloat64 y\n---\nfloat64 result\n", "mult_msgs", "Mult")
    assert isinstance(spec, ServiceSpec)
    assert spec.type_name == "mult_msgs/srv/Mult"
    assert spec.request.type_name == "mult_msgs/srv/Mult_Request"
    assert spec.response.type_name == "mult_msgs/srv/Mult_Response"
    assert [f.name for f in spec.request.fields] == ["x", "y"]
    assert spec.response.fields[0].line == 5
    assert spec.request.source == "# c\nfloat64 x\nfloat64 y\n"


def test_empty_service_parts() -> None:
    """A service with empty request and response is valid (like std_srvs/Empty)."""
    spec = parse_service("---\n", "std_srvs", "Empty")
    assert spec.request.fields == () and spec.response.fields == ()


def test_action_parts() -> None:
    """An action splits into Goal, Result and Feedback."""
    spec = parse_action("int32 order\n---\nint32[] sequence\n---\nint32[] sequence\n", "p", "Fib")
    assert isinstance(spec, ActionSpec)
    assert [m.name for m in (spec.goal, spec.result, spec.feedback)] == [
        "Fib_Goal",
        "Fib_Result",
        "Fib_Feedback",
    ]
    assert spec.feedback.type_name == "p/action/Fib_Feedback"
    assert spec.feedback.fields[0].line == 5


def test_parse_file_takes_package_and_kind_from_path(tmp_path: Path) -> None:
    """parse_file reads <pkg>/<kind>/Name.<kind> and names the package from the path."""
    (tmp_path / "my_pkg" / "srv").mkdir(parents=True)
    path = tmp_path / "my_pkg" / "srv" / "Do.srv"
    path.write_text("int32 a\n---\nint32 b\n")
    spec = parse_file(path)
    assert isinstance(spec, ServiceSpec)
    assert spec.type_name == "my_pkg/srv/Do" and spec.file == str(path)


BAD_DEFINITIONS = [
    ("int32 a\nflaot64 b\n", 2, "unknown type 'flaot64'"),
    ("int32\n", 1, "expected 'TYPE NAME"),
    ("int32 Bad\n", 1, "invalid field name 'Bad'"),
    ("int32 a__b\n", 1, "invalid field name"),
    ("int32 a_\n", 1, "invalid field name"),
    ("int32 a\nint32 a\n", 2, "duplicate name 'a'"),
    ("int32 lower=5\n", 1, "invalid constant name 'lower'"),
    ("int32[3] X=5\n", 1, "must have a primitive scalar type"),
    ("Header X=5\n", 1, "must have a primitive scalar type"),
    ("int32 X=\n", 1, "has no value"),
    ("int8 a 128\n", 1, "out of range"),
    ("uint8 X=-1\n", 1, "out of range"),
    ("int32 a 1.5\n", 1, "invalid int32 value"),
    ("float32 a 1e39\n", 1, "float32 value 1e39 out of range"),
    ("float64 a abc\n", 1, "invalid float64 value"),
    ("bool a yes\n", 1, "invalid bool value"),
    ('string<=3 a "toolong"\n', 1, "longer than its bound 3"),
    ('string a "unterminated\n', 1, "unterminated string literal"),
    ("int32[3] a [1, 2]\n", 1, "has 2 values, the array has 3"),
    ("int32[<=1] a [1, 2]\n", 1, "more than the bound 1"),
    ("int32[] a 5\n", 1, "array default must be written"),
    ("int32[] a [1,,2]\n", 1, "malformed array default"),
    ("int32[0] a\n", 1, "array size must be a positive integer"),
    ("int32[x] a\n", 1, "array size must be a positive integer"),
    ("int32[<=0] a\n", 1, "sequence bound must be a positive integer"),
    ("string<=0 a\n", 1, "string bound must be a positive integer"),
    ("int32<=3 a\n", 1, "only strings take a <=N bound"),
    ("int32[3 a\n", 1, "malformed array type"),
    ("Header h 5\n", 1, "cannot have a default"),
    ("Bad-Pkg/Type a\n", 1, "invalid package name"),
    ("a/b/c/D x\n", 1, "invalid type"),
    ("pkg/lower x\n", 1, "unknown type 'pkg/lower'"),
]


@pytest.mark.parametrize(("text", "line", "reason"), BAD_DEFINITIONS)
def test_bad_definitions_name_file_line_and_reason(text: str, line: int, reason: str) -> None:
    """Each malformed line raises DefinitionError with file, line and the reason."""
    with pytest.raises(DefinitionError) as info:
        parse_message("# comment\n" + text, "pkg", "T", file="pkg/msg/T.msg")
    err = info.value
    assert err.file == "pkg/msg/T.msg"
    assert err.line == line + 1
    assert reason in err.reason
    assert str(err).startswith(f"pkg/msg/T.msg:{line + 1}: ")


def test_service_error_line_counts_from_file_start() -> None:
    """An error in a response names its line in the whole .srv file."""
    with pytest.raises(DefinitionError) as info:
        parse_service("int32 a\n---\nint32 b\nbogus c\n", "pkg", "S", file="S.srv")
    assert (info.value.file, info.value.line) == ("S.srv", 4)


@pytest.mark.parametrize(
    ("text", "count"),
    [("int32 a\n", 0), ("a0 b\n---\n---\n", 2)],
)
def test_service_needs_exactly_one_separator(text: str, count: int) -> None:
    """A .srv with no or two '---' lines is rejected, naming how many were found."""
    with pytest.raises(DefinitionError, match=f"found {count}"):
        parse_service(text, "pkg", "S", file="S.srv")


def test_action_needs_two_separators() -> None:
    """An .action with one '---' is rejected."""
    with pytest.raises(DefinitionError, match="expected 2 '---' separator"):
        parse_action("int32 a\n---\nint32 b\n", "pkg", "A", file="A.action")


def test_bad_file_name_and_suffix(tmp_path: Path) -> None:
    """parse_file rejects invalid type names and unknown suffixes, naming the file."""
    bad_name = tmp_path / "pkg" / "msg" / "lower.msg"
    bad_name.parent.mkdir(parents=True)
    bad_name.write_text("int32 a\n")
    with pytest.raises(DefinitionError, match="invalid type name 'lower'") as info:
        parse_file(bad_name)
    assert info.value.file == str(bad_name)
    bad_suffix = tmp_path / "pkg" / "msg" / "Thing.idl"
    bad_suffix.write_text("")
    with pytest.raises(DefinitionError, match="unknown definition suffix"):
        parse_file(bad_suffix)


def test_invalid_package_name() -> None:
    """parse_message rejects a package name that is not lower_case."""
    with pytest.raises(DefinitionError, match="invalid package name 'Pkg'"):
        parse_message("int32 a\n", "Pkg", "T")
