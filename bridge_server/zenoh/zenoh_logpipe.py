"""Zenoh's own log lines, read before they reach the process's output.

Zenoh (Rust) writes its log with ``tracing`` straight to file descriptor 1 (standard output:
``zenoh.init_log_from_env_or`` says so): Python's ``logging`` never sees it.
:func:`filter_zenoh_log` puts a pipe on descriptor 1 and a daemon thread reading it: each
line goes to a handler, which passes it on to the real standard output, rewrites it or drops
it. Python's own writes (``sys.stdout``) go to the real standard output directly, and its
log goes to standard error, so a handler that logs does not feed its own pipe.
"""

from __future__ import annotations

import os
import sys
import threading
from collections.abc import Callable

__all__ = ["LineHandler", "filter_zenoh_log"]

LineHandler = Callable[[str], "str | None"]
"""Given a line Zenoh wrote (without its newline), what to write instead (``None``:
nothing)."""

_installed: list[LineHandler] = []


def filter_zenoh_log(handler: LineHandler) -> None:
    """Route file descriptor 1 through ``handler`` for the rest of the process (once per
    process: a second call replaces the handler). ``sys.stdout`` is pointed at the real
    standard output, so Python's own writes bypass the filter."""
    if _installed:
        _installed[0] = handler
        return
    _installed.append(handler)
    sys.stdout.flush()
    real = os.dup(1)
    read, write = os.pipe()
    os.dup2(write, 1)
    os.close(write)
    sys.stdout = open(real, "w", buffering=1, encoding="utf-8",  # noqa: SIM115 (the process's)
                      errors="backslashreplace", closefd=False)
    threading.Thread(target=_pump, args=(read, real), daemon=True,
                     name="zenoh-log").start()


def _pump(read: int, real: int) -> None:
    """Read descriptor 1's pipe line by line, writing what the handler says to ``real``."""
    with open(read, "rb") as pipe:
        for raw in iter(pipe.readline, b""):
            line = raw.decode("utf-8", "backslashreplace").rstrip("\n")
            try:
                out = _installed[0](line)
            except Exception as exc:  # a handler's bug must not eat Zenoh's log
                out = f"{line}\n(Zenoh log filter failed: {exc!r})"
            if out is not None:
                os.write(real, (out + "\n").encode("utf-8", "backslashreplace"))
