"""How the bridge's programs end: with their own exit status, whatever other threads do.

A Python thread that is inside C++ code when the interpreter finalises (rclpy's executor
waiting in ``rcl_wait``, a Fast DDS or Zenoh callback) is ended by CPython with
``pthread_exit`` as soon as it asks for the GIL back; the unwind that starts crosses
pybind11's ``noexcept`` frames and libstdc++ calls ``std::terminate``: the process prints
``terminate called without an active exception`` and dies of SIGABRT (exit 134) instead of
the status it chose. C++ static destructors of joinable threads end the same way. Issue 43
saw 1 bridge start refusal in 30 abort so; a plain rclpy process with an executor thread
aborts nearly every time it exits while that thread spins with short waits.

:func:`exit_process` therefore ends the process without finalising the interpreter, once
what must reach its destination has: the log handlers (flushed and closed) and stdout and
stderr. Python's ``atexit`` callbacks are not run (the programs' own shutdown comes first:
the bridge closes its node, the relay its Zenoh session).
"""

from __future__ import annotations

import contextlib
import functools
import logging
import os
import sys
import traceback
from typing import NoReturn, Protocol

__all__ = ["Main", "ends_process", "exit_process"]


class Main(Protocol):
    """A program's ``main``: ``argv`` (default ``sys.argv[1:]``) -> its exit status."""

    def __call__(self, argv: list[str] | None = None) -> int: ...


def exit_process(status: int) -> NoReturn:
    """Flush and close the log handlers, flush stdout and stderr, then ``os._exit(status)``."""
    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):  # a closed pipe: nothing more can be said
            stream.flush()
    os._exit(status)


def ends_process(main: Main) -> Main:
    """A program's ``main(argv=None)`` that, run as the program (no ``argv``), ends the process
    with its status through :func:`exit_process`; with an ``argv`` (in-process callers such as
    tests) it returns the status as before."""

    @functools.wraps(main)
    def run(argv: list[str] | None = None) -> int:
        if argv is not None:
            return main(argv)
        try:
            status = main(argv)
        except Exception:  # a bug: its traceback, and exit 1 as Python would
            traceback.print_exc()
            status = 1
        exit_process(status)

    return run
