"""The user API is declared once: ``Ros`` (api.py) is the front, ``RosBase`` (ros.py), itself.

There is no second copy of its methods and overloads to keep in step (api.py used to
restate them as a Protocol); both backends are the front over another transport, and
``tests/client/test_api_types.py`` checks that mypy sees them as ``Ros``.
"""

from __future__ import annotations

import inspect

import roslibpy_lite
from roslibpy_lite import api
from roslibpy_lite.ros import RosBase


def test_ros_is_the_front_itself() -> None:
    """``Ros`` everywhere it is exported is ``RosBase``, and both backends are one."""
    assert api.Ros is RosBase
    assert roslibpy_lite.Ros is RosBase
    assert issubclass(roslibpy_lite.Client, RosBase)
    assert issubclass(roslibpy_lite.MockRos, RosBase)


def test_no_module_restates_the_api() -> None:
    """No class in the client outside ros.py declares the front's public methods again (a
    Protocol copy of it, say): an API change is written in one place."""
    front = {n for n, v in vars(RosBase).items() if not n.startswith("_") and callable(v)}
    import pkgutil

    for info in pkgutil.walk_packages(roslibpy_lite.__path__, "roslibpy_lite."):
        if info.name.startswith(("roslibpy_lite.cli", "roslibpy_lite.sync", "roslibpy_lite.compat")):
            continue  # the blocking client and the drop-in have their own return types
        module = __import__(info.name, fromlist=["_"])
        for name, cls in vars(module).items():
            if not inspect.isclass(cls) or cls.__module__ != info.name or issubclass(cls, RosBase):
                continue
            own = {n for n in vars(cls) if not n.startswith("_")}
            restated = own & front
            assert len(restated) < 5, f"{info.name}.{name} restates {sorted(restated)}"
