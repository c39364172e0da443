"""Helpers of the blocking client's tests."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from roslibpy_lite import sync
from tests.helpers import send_until_heard_sync


def heard(
    pub: sync.Publisher[Any], sub: sync.Subscription[Any], msg: Any,
    wanted: Callable[[Any], bool] = lambda msg: True, timeout: float = 15.0,
) -> Any:
    """Publish ``msg`` until ``sub`` hears a ``wanted`` message (ROS discovery has no event)."""

    def listen(wait: float) -> Any:
        got = sub.get(wait)
        if got is None or not wanted(got):
            raise TimeoutError
        return got

    return send_until_heard_sync(lambda: pub.publish(msg), listen,
                                 f"{msg} on {sub.topic}", timeout=timeout)


def skip_repeats(sub: sync.Subscription[Any], value: Any) -> Any:
    """The first message that is not a repeat of ``value`` (left over by :func:`heard`)."""
    while (msg := sub.get(10)) == value:
        pass
    return msg
