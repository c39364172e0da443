"""One clear line instead of a traceback when the bridge's dependencies are not installed.

A client-only install (the wheel without the ``bridge`` extra) carries the
``bridge_server`` package but not ROS 2, numpy or cbor2; starting the bridge
there must say what to install.
"""

from __future__ import annotations

import sys
from typing import NoReturn

__all__ = ["INSTALL_HINT", "missing_dependency"]

INSTALL_HINT = (
    "python -m pip install '.[{extra}]' in a virtual environment, from a checkout of the "
    "roslibpy-lite repository (the project is not on PyPI; docs/ros-on-pypi.md)"
)

_OURS = ("bridge_server", "roslibpy_lite", "msgs")


def missing_dependency(exc: ModuleNotFoundError, extra: str = "bridge") -> NoReturn:
    """Exit with status 2 and one line naming the missing module and the extra to install
    (``bridge``, or ``relay`` for ``roslibpy-lite-relay``).

    A missing module of our own packages is a bug, not a missing extra: it is re-raised.
    """
    name = exc.name or "?"
    if name.split(".")[0] in _OURS:
        raise exc
    program = "roslibpy-lite-relay" if extra == "relay" else "roslibpy-lite-bridge"
    print(f"{program}: the {extra}'s dependencies are not installed (no module "
          f"named {name!r}); install them with: {INSTALL_HINT.format(extra=extra)}",
          file=sys.stderr)
    raise SystemExit(2)
