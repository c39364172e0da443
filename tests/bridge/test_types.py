"""Type-name parsing and resolution (bridge_server.rclpy_graph.types) against the installed rclpy packages."""

from __future__ import annotations

import sys

import pytest

from bridge_server.rclpy_graph.types import (
    BridgeError,
    TypeName,
    TypeNameError,
    UnknownTypeError,
    canonical_name,
    parse_type_name,
    resolve_action,
    resolve_message,
    resolve_service,
    type_name_of,
)


def test_message_both_spellings_resolve_to_the_rclpy_class() -> None:
    """`std_msgs/String` and `std_msgs/msg/String` give the same rclpy class."""
    from std_msgs.msg import String

    assert resolve_message("std_msgs/String") is String
    assert resolve_message("std_msgs/msg/String") is String


def test_service_both_spellings_resolve_with_request_and_response() -> None:
    """Both service spellings give the srv class, which has Request and Response."""
    from std_srvs.srv import SetBool

    assert resolve_service("std_srvs/SetBool") is SetBool
    assert resolve_service("std_srvs/srv/SetBool") is SetBool
    assert resolve_service("std_srvs/SetBool").Request().data is False
    assert hasattr(resolve_service("std_srvs/srv/SetBool"), "Response")


def test_action_both_spellings_resolve() -> None:
    """Both action spellings give the action class with Goal, Result and Feedback."""
    from test_msgs.action import Fibonacci

    assert resolve_action("test_msgs/Fibonacci") is Fibonacci
    assert resolve_action("test_msgs/action/Fibonacci") is Fibonacci


def test_project_interface_package_resolves() -> None:
    """Our own interface package built into the venv (mult_msgs) resolves like any other."""
    cls = resolve_service("mult_msgs/MultFloats")
    assert type_name_of(cls) == "mult_msgs/srv/MultFloats"


def test_canonical_spelling() -> None:
    """The canonical spelling always has the kind in the middle."""
    assert canonical_name("std_msgs/String", "msg") == "std_msgs/msg/String"
    assert canonical_name("std_msgs/msg/String", "msg") == "std_msgs/msg/String"
    assert canonical_name("std_srvs/Empty", "srv") == "std_srvs/srv/Empty"
    assert parse_type_name("a_b/Type_1", "action") == TypeName("a_b", "action", "Type_1")


def test_type_name_of_classes() -> None:
    """type_name_of answers pkg/kind/Type for messages, services, their parts and actions."""
    from geometry_msgs.msg import PoseStamped
    from std_srvs.srv import SetBool
    from test_msgs.action import Fibonacci

    assert type_name_of(PoseStamped) == "geometry_msgs/msg/PoseStamped"
    assert type_name_of(SetBool) == "std_srvs/srv/SetBool"
    assert type_name_of(SetBool.Request) == "std_srvs/srv/SetBool_Request"
    assert type_name_of(Fibonacci) == "test_msgs/action/Fibonacci"
    assert type_name_of(Fibonacci.Goal) == "test_msgs/action/Fibonacci_Goal"
    with pytest.raises(TypeError):
        type_name_of(int)


@pytest.mark.parametrize(
    "name",
    [
        "std_msgs",
        "a/b/c/d",
        "std_msgs/msg/",
        "std_msgs/",
        "/String",
        "std_msgs//String",
        "",
        "std msgs/String",
        "std_msgs/String.msg",
        "std_msgs/foo/String",
        "../etc/passwd",
        "std_msgs/msg/String/",
    ],
)
def test_malformed_names_raise_type_name_error(name: str) -> None:
    """Malformed type strings are TypeNameError naming the string."""
    with pytest.raises(TypeNameError) as info:
        resolve_message(name)
    assert repr(name) in str(info.value)
    assert isinstance(info.value, BridgeError)
    assert isinstance(info.value, ValueError)


def test_non_string_type_is_type_name_error() -> None:
    """A JSON number or null where a type string belongs is a TypeNameError."""
    for bad in (5, None, ["std_msgs/String"]):
        with pytest.raises(TypeNameError):
            resolve_message(bad)


def test_wrong_kind_is_type_name_error() -> None:
    """A service name given where a message type is expected (and vice versa) is rejected."""
    with pytest.raises(TypeNameError, match="srv type where a msg type is expected"):
        resolve_message("std_srvs/srv/Empty")
    with pytest.raises(TypeNameError, match="msg type where a srv type is expected"):
        resolve_service("std_msgs/msg/String")


@pytest.mark.parametrize(
    ("resolve", "name"),
    [
        (resolve_message, "std_msgs/Nope"),
        (resolve_message, "std_msgs/msg/Nope"),
        (resolve_message, "no_such_pkg/String"),
        (resolve_message, "std_srvs/SetBool"),
        (resolve_service, "std_msgs/String"),
        (resolve_service, "std_srvs/srv/Nope"),
        (resolve_action, "test_msgs/action/Nope"),
        (resolve_action, "std_msgs/String"),
    ],
)
def test_unknown_names_raise_unknown_type_error(resolve: object, name: str) -> None:
    """Well-formed names that no installed package provides are UnknownTypeError naming them."""
    assert callable(resolve)
    with pytest.raises(UnknownTypeError) as info:
        resolve(name)
    assert repr(name) in str(info.value)
    assert isinstance(info.value, BridgeError)


def test_resolution_never_imports_arbitrary_modules() -> None:
    """A client naming a non-ROS Python module cannot make the bridge import it."""
    sys.modules.pop("antigravity", None)
    with pytest.raises(UnknownTypeError):
        resolve_message("antigravity/Foo")
    assert "antigravity" not in sys.modules
    with pytest.raises(UnknownTypeError):
        resolve_message("os/path")


def test_resolution_is_cached() -> None:
    """A second lookup returns the very same class object."""
    assert resolve_message("geometry_msgs/Twist") is resolve_message("geometry_msgs/msg/Twist")
