"""The event loop a server runs on: ``--event-loop`` of the bridge and of the relay."""

from __future__ import annotations

import argparse
import asyncio
from collections.abc import Callable

from rosbridge_core.interfaces import BridgeError

__all__ = ["EVENT_LOOPS", "add_argument", "event_loop_factory", "loop_name"]

EVENT_LOOPS = ("auto", "asyncio", "uvloop")
"""What ``--event-loop`` may ask for (see :func:`event_loop_factory`)."""


def add_argument(p: argparse.ArgumentParser, server: str) -> None:
    """``--event-loop`` on ``server``'s command line (``server``: what the help names)."""
    p.add_argument(
        "--event-loop",
        choices=EVENT_LOOPS,
        default="auto",
        help=f"the event loop the {server} runs on: uvloop (libuv's, its loop and sockets in "
        "C), asyncio (the standard library's) or auto (uvloop where it is installed, as the "
        "bridge extra does on Linux and macOS; default auto)",
    )


def event_loop_factory(kind: str) -> Callable[[], asyncio.AbstractEventLoop] | None:
    """What makes the loop for ``--event-loop kind`` (``None``: asyncio's own).

    uvloop runs the loop, its timers and the sockets' reads and writes in C, where asyncio
    runs each turn of the loop and each callback's handle in Python: that was a third of
    the Python a client-served service call cost the bridge, and on a relay it halved the
    CPU of a camera frame to each of 100 viewers (asyncio copies what the socket does not
    take at once into a buffer of its own). ``auto`` takes it where it is installed.
    Raises :class:`BridgeError` if ``uvloop`` is asked for and not installed.
    """
    if kind not in EVENT_LOOPS:
        raise BridgeError(f"--event-loop {kind!r}: expected one of {', '.join(EVENT_LOOPS)}")
    if kind == "asyncio":
        return None
    try:
        import uvloop
    except ImportError as exc:
        if kind == "uvloop":
            raise BridgeError(f"--event-loop uvloop: uvloop cannot be imported ({exc}); "
                              "install it (pip install uvloop, or the bridge extra)") from None
        return None
    return uvloop.new_event_loop


def loop_name(loop: asyncio.AbstractEventLoop) -> str:
    """The running loop's kind, as the start-up log names it (``uvloop``, ``asyncio``)."""
    return type(loop).__module__.partition(".")[0]
