"""The decode budget's options, shared by the bridge's and the relay's command lines.

Every CDR message the server decodes (a relay's robot's samples, a Foxglove client's
``cdr`` publish, a recording) may cost at most ``max(floor, per_byte * its size)`` bytes
decoded (:class:`msgs.cdr.Budget`); past it the decode fails at the field whose elements
would pass it, naming the field and the budget, and nothing over it is made.

A message of :data:`OFF_LOOP_BYTES` or more is decoded (and encoded) on one of
:func:`workers`' threads rather than on the event loop, in order per topic
(:class:`~rosbridge_core.codec.lane.OrderedLane`, for :mod:`bridge_server.zenoh.decode` and
:mod:`bridge_server.foxglove.inbound`).
"""

from __future__ import annotations

import argparse
import concurrent.futures
import threading

from msgs import cdr

__all__ = ["OFF_LOOP_BYTES", "WORKERS", "add_arguments", "apply", "budget_from_args",
           "close_workers", "explain", "workers"]

OFF_LOOP_BYTES = 64 * 1024
"""Messages of this many bytes or more are decoded and encoded on a worker thread: below it
a message costs the loop at most a few milliseconds, whatever it holds (the budget's floor
aside: 64 KiB of empty structs decode in ~20 ms)."""

WORKERS = 2
"""Threads that decode large messages (the interpreter's lock is shared: more would not make
them faster)."""

_pool: concurrent.futures.ThreadPoolExecutor | None = None
_pool_lock = threading.Lock()


def workers() -> concurrent.futures.ThreadPoolExecutor:
    """The process's pool of threads that decode and encode large messages."""
    global _pool
    with _pool_lock:
        if _pool is None:
            _pool = concurrent.futures.ThreadPoolExecutor(WORKERS, "decode")
        return _pool


def close_workers() -> None:
    """End the pool's threads, once what they were given is done (a process that served
    relays in-process and ends without the interpreter's exit: a test session); the next
    large message makes a new pool."""
    global _pool
    with _pool_lock:
        pool, _pool = _pool, None
    if pool is not None:
        pool.shutdown(wait=True)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """``--decode-budget-per-byte`` and ``--decode-budget-floor``."""
    default = cdr.DEFAULT_BUDGET
    p.add_argument(
        "--decode-budget-per-byte", type=int, default=default.per_byte, metavar="N",
        help="a CDR message the server decodes may cost N bytes of memory decoded per byte of "
        f"it (default {default.per_byte}; with --decode-budget-floor); one over it is refused "
        "naming the field, before its elements are made")
    p.add_argument(
        "--decode-budget-floor", type=int, default=default.floor, metavar="BYTES",
        help="what any message may cost decoded, whatever its size (default "
        f"{default.floor}, {default.floor >> 20} MiB)")


def explain(exc: BaseException) -> str:
    """The text of a decode's error, with the options that set the budget when it was over
    it (what to change if the message was a real one)."""
    if isinstance(exc, cdr.BudgetError):
        return f"{exc} (--decode-budget-per-byte, --decode-budget-floor)"
    return str(exc)


def budget_from_args(args: argparse.Namespace) -> cdr.Budget:
    """The budget the options give; ``ValueError`` naming the option that is wrong."""
    if args.decode_budget_per_byte < 1:
        raise ValueError(f"--decode-budget-per-byte {args.decode_budget_per_byte}: expected 1 "
                         "or more")
    if args.decode_budget_floor < 0:
        raise ValueError(f"--decode-budget-floor {args.decode_budget_floor}: expected 0 or "
                         "more bytes")
    return cdr.Budget(args.decode_budget_per_byte, args.decode_budget_floor)


def apply(args: argparse.Namespace) -> None:
    """Decode every message of this process within the options' budget."""
    cdr.set_budget(budget_from_args(args))
