"""For mypy only: both backends satisfy the :class:`~roslibpy_lite.api.Ros` protocol.

``mypy roslibpy_lite`` checks this module; nothing imports it at run time.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .api import Ros
    from .client import Client
    from .mock import MockRos


def _backends(mock: MockRos, client: Client) -> tuple[Ros, Ros]:
    """Fails type checking when a backend lacks a method of the protocol (or its signature)."""
    return mock, client
