"""A port for a listener that must be named before it listens (a Zenoh router, a relay, a
load balancer, a peer server), for the benchmarks and the tests.

Asking the kernel for port 0 and closing the socket returns a port from the *ephemeral*
range (``net.ipv4.ip_local_port_range``, 32768-60999 by default), the same range the
kernel draws from for every outgoing connection and every other ``port=0`` listener: by
the time the program binds the number, a websocket server started with port 0 or a client's
connection may hold it (seen in CI: a relay's own websocket server took the number picked
for its Zenoh listener). The ports here come from below that range, where the kernel never
assigns one by itself, each process (each pytest-xdist worker) in a block of its own, in
turn, skipping any that cannot be bound now.
"""

from __future__ import annotations

import itertools
import os
import socket
import threading

__all__ = ["free_port"]

_BLOCK = 1_000  # ports per process
_BLOCKS = 16  # processes with distinct blocks (pytest-xdist workers, a bench run)
_FLOOR = 12_000  # 12,000-27,999: below any ephemeral range Linux ships with


def _ephemeral_low() -> int:
    try:
        with open("/proc/sys/net/ipv4/ip_local_port_range") as f:
            return int(f.read().split()[0])
    except (OSError, ValueError, IndexError):
        return 32768


def _block() -> int:
    """This process's block: its xdist worker number (``gw3`` → 3), else its pid."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")
    n = int(worker[2:]) if worker[2:].isdigit() else os.getpid()
    return n % _BLOCKS


_next = itertools.count()
_lock = threading.Lock()


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port nobody holds now on ``host`` that no ``port=0`` listener or outgoing
    connection will be given meanwhile (see the module's text)."""
    low = _FLOOR + _block() * _BLOCK
    if low + _BLOCK > _ephemeral_low():  # a machine with a widened range: the kernel's pick
        with socket.socket() as s:
            s.bind((host, 0))
            return int(s.getsockname()[1])
    for _ in range(_BLOCK):
        with _lock:
            port = low + next(_next) % _BLOCK
        with socket.socket() as s:
            try:
                s.bind((host, port))
            except OSError:  # held, or in TIME_WAIT: the next one
                continue
            return port
    raise RuntimeError(f"no free port in {low}-{low + _BLOCK - 1}")
