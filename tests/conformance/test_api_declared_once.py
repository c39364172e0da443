"""The ``Ros`` protocol (api.py) declares exactly what ``RosBase`` (ros.py, the source) offers.

mypy checks that the backends satisfy the protocol (``_typecheck.py``), which lets
the protocol lag behind the front (a new method, a narrower overload, another
default); this test makes every difference a failure, so an API change made in
``ros.py`` must be made in ``api.py`` in the same commit.
"""

from __future__ import annotations

import inspect
import typing
from collections.abc import Callable
from typing import Any

import pytest

from roslibpy_lite.api import Ros
from roslibpy_lite.ros import RosBase

_PROTOCOL_ONLY = {"_is_protocol", "_is_runtime_protocol"}


def _public(cls: type) -> dict[str, Any]:
    """The public members ``cls`` defines itself or inherits below ``object``, by name."""
    names = {
        n for klass in cls.__mro__ if klass not in (object, typing.Protocol, typing.Generic)
        for n in vars(klass)
        if (not n.startswith("_") or n in {"__aenter__", "__aexit__"}) and n not in _PROTOCOL_ONLY
    }
    return {n: inspect.getattr_static(cls, n) for n in names}


def _shape(member: Any) -> list[str]:
    """A member's signature and those of its overloads, as text (annotations as written)."""
    fn: Callable[..., Any] = member
    if isinstance(member, property):
        assert member.fget is not None
        fn = member.fget
    kind = "property" if isinstance(member, property) else (
        "async" if inspect.iscoroutinefunction(fn) else "def")
    return [f"{kind} {inspect.signature(fn)}",
            *(f"overload {inspect.signature(o)}" for o in typing.get_overloads(fn))]


def test_the_same_public_names() -> None:
    """Every public member of the front is in the protocol, and nothing else is."""
    assert sorted(_public(Ros)) == sorted(_public(RosBase))


@pytest.mark.parametrize("name", sorted(_public(Ros)))
def test_the_same_signature_and_overloads(name: str) -> None:
    """Each member has the same kind, signature, defaults and overloads in both."""
    assert _shape(_public(Ros)[name]) == _shape(_public(RosBase)[name])


def test_the_check_sees_an_overload_missing() -> None:
    """A function with one overload fewer has another shape."""
    @typing.overload
    def f(x: int) -> int: ...
    @typing.overload
    def f(x: str) -> str: ...
    def f(x: Any) -> Any:
        return x

    def g(x: Any) -> Any:
        return x

    assert _shape(f) != _shape(g)
