"""Helpers of the blocking client's tests."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from roslibpy_lite import RosTimeoutError, sync


def heard(
    pub: sync.Publisher[Any], sub: sync.Subscription[Any], msg: Any,
    wanted: Callable[[Any], bool] = lambda msg: True, timeout: float = 15.0,
) -> Any:
    """Publish ``msg`` until ``sub`` hears a ``wanted`` message (ROS discovery has no event)."""
    deadline = time.monotonic() + timeout
    while True:
        pub.publish(msg)
        try:
            got = sub.get(0.25)
        except RosTimeoutError:
            got = None
        if got is not None and wanted(got):
            return got
        if time.monotonic() > deadline:
            raise RosTimeoutError(f"{sub.topic}: never heard {msg}")


def skip_repeats(sub: sync.Subscription[Any], value: Any) -> Any:
    """The first message that is not a repeat of ``value`` (left over by :func:`heard`)."""
    while (msg := sub.get(10)) == value:
        pass
    return msg
