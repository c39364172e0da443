"""``--workers N``: N bridge processes on one port, and how they see each other.

The supervisor (this process, no rclpy) reserves the port with
``SO_REUSEPORT`` (bound, not listening, so the kernel hands it no
connection), then starts N workers: ``python -m bridge_server`` with the same
options plus ``--worker-index i --worker-dir D``. Each worker listens on the
same port with ``SO_REUSEPORT`` (the kernel spreads new connections across
them) and joins the ROS graph as its own node (``<node name>_w<i>``), so DDS
carries messages, latched topics and service calls between workers like
between any two nodes.

The whole bridge in one view: each worker also listens on a unix socket
``D/worker-<i>.sock`` that answers with its snapshot
(:func:`bridge_server.http.snapshot.take`) as JSON. Whichever worker answers
``/metrics`` or ``/status.json`` asks the others and merges
(:func:`bridge_server.http.snapshot.merge`). A counter of a restarted worker starts
again from zero (Prometheus sees a counter reset).

The supervisor relays the workers' logs, prints the ready line once every
worker listens, restarts a worker that dies (at most once a second each),
passes SIGHUP on to them (each reloads its certificates and auth file), and
on SIGINT/SIGTERM stops them all: SIGTERM, then SIGKILL after
:data:`STOP_GRACE` seconds. A supervisor that is killed outright cannot do that,
so each worker also stops when its stdin pipe from the supervisor reaches
end-of-file (:func:`watch_supervisor`): no orphaned worker keeps the port.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from typing import IO

__all__ = ["STOP_GRACE", "Supervisor", "watch_supervisor"]

log = logging.getLogger("bridge_server.http.workers")

STOP_GRACE = 0.8
"""Seconds workers get to stop after SIGTERM before they are killed."""

_WORKER_READY = re.compile(r"bridge_server worker (\d+) listening")


def watch_supervisor(stop: asyncio.Event) -> None:
    """In a worker: set ``stop`` when the supervisor is gone (end-of-file on stdin).

    The supervisor holds the other end of the worker's stdin pipe and never
    writes to it; the kernel closes it when the supervisor exits however it
    exits, so a killed supervisor does not leave workers serving its port.
    """
    loop = asyncio.get_running_loop()
    fd = sys.stdin.fileno()

    def readable() -> None:
        if os.read(fd, 4096):
            return  # nobody writes here; ignore anything that does
        loop.remove_reader(fd)
        log.warning("the supervisor is gone: worker stopping")
        stop.set()

    loop.add_reader(fd, readable)


def reserve(host: str, port: int) -> socket.socket:
    """Bind (without listening) ``host:port`` with SO_REUSEPORT: holds the port for workers."""
    sock = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
    sock.bind((host, port))
    return sock


class Supervisor:
    """Starts, watches, restarts and stops the worker processes."""

    def __init__(self, argv: list[str], workers: int, host: str, port: int,
                 metrics_port: int | None) -> None:
        self.argv = _without_workers(argv)
        self.n = workers
        self.host = host
        self.reserved = [reserve(host, port)]
        self.port = self.reserved[0].getsockname()[1]
        self.metrics_port = metrics_port
        if metrics_port is not None:
            self.reserved.append(reserve(host, metrics_port))
            self.metrics_port = self.reserved[-1].getsockname()[1]
        self.dir = tempfile.mkdtemp(prefix="roslibpy-bridge-workers-")
        self.procs: list[subprocess.Popen[bytes] | None] = [None] * workers
        self.started_at = [0.0] * workers
        self.ready = [threading.Event() for _ in range(workers)]
        self.stop = threading.Event()

    def _spawn(self, i: int) -> None:
        self.ready[i].clear()  # set again by its ready line
        extra = ["--port", str(self.port), "--worker-index", str(i), "--worker-dir", self.dir]
        if self.metrics_port is not None:
            extra += ["--metrics-port", str(self.metrics_port)]
        proc = subprocess.Popen(
            [sys.executable, "-m", "bridge_server", *self.argv, *extra],
            # Never written: when the supervisor dies, even by SIGKILL, the worker reads
            # end-of-file here and stops (see watch_supervisor), so no worker is orphaned.
            stdin=subprocess.PIPE,
            stderr=subprocess.PIPE,
            process_group=0,  # terminal signals reach the supervisor only
        )
        self.procs[i] = proc
        self.started_at[i] = time.monotonic()
        assert proc.stderr is not None
        threading.Thread(target=self._relay, args=(i, proc.stderr), daemon=True,
                         name=f"worker-{i}-log").start()

    def _relay(self, i: int, stream: IO[bytes]) -> None:
        for raw in stream:
            line = raw.decode(errors="replace").rstrip()
            if _WORKER_READY.search(line):
                self.ready[i].set()
            sys.stderr.write(f"[w{i}] {line}\n")
            sys.stderr.flush()

    def run(self) -> int:
        """Run until SIGINT/SIGTERM; the exit status."""
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: self.stop.set())
        signal.signal(signal.SIGHUP, lambda *_: self._forward(signal.SIGHUP))  # reload
        try:
            for i in range(self.n):
                self._spawn(i)
            deadline = time.monotonic() + 60
            while not all(e.is_set() for e in self.ready):
                if self.stop.wait(0.05) or time.monotonic() > deadline:
                    break
                procs = enumerate(self.procs)
                dead = [i for i, p in procs if p is not None and p.poll() is not None]
                if dead:
                    log.error("worker %d exited before listening", dead[0])
                    return 1
            if self.stop.is_set():
                return 0
            if not all(e.is_set() for e in self.ready):
                log.error("workers did not start within 60 s")
                return 1
            scheme = "wss" if any(a.startswith("--certfile") for a in self.argv) else "ws"
            log.info("bridge_server listening on %s://%s:%d (%d workers)", scheme, self.host,
                     self.port, self.n)
            while not self.stop.wait(0.1):
                self._restart_dead()
            log.info("bridge_server shutting down")
            return 0
        finally:
            self._stop_all()

    def _forward(self, sig: int) -> None:
        """Pass ``sig`` on to every listening worker (SIGHUP: each reloads its files; one
        still starting reads them anyway, and would not survive the signal yet)."""
        for i, proc in enumerate(self.procs):
            if proc is not None and proc.poll() is None and self.ready[i].is_set():
                with contextlib.suppress(ProcessLookupError):
                    proc.send_signal(sig)

    def _restart_dead(self) -> None:
        for i, proc in enumerate(self.procs):
            if proc is None or proc.poll() is None:
                continue
            if time.monotonic() - self.started_at[i] < 1.0:
                continue  # crashing at once: retry at most once a second
            log.error("worker %d (pid %d) exited with status %s; restarting it", i, proc.pid,
                      proc.returncode)
            self._spawn(i)

    def _stop_all(self) -> None:
        procs = [p for p in self.procs if p is not None and p.poll() is None]
        for p in procs:
            with contextlib.suppress(ProcessLookupError):
                p.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + STOP_GRACE
        for p in procs:
            try:
                p.wait(max(deadline - time.monotonic(), 0.01))
            except subprocess.TimeoutExpired:
                log.warning("worker pid %d did not stop in %.1f s; killing it", p.pid, STOP_GRACE)
                p.kill()
                p.wait()
        for s in self.reserved:
            s.close()
        shutil.rmtree(self.dir, ignore_errors=True)


def _without_workers(argv: list[str]) -> list[str]:
    out: list[str] = []
    skip = False
    for a in argv:
        if skip:
            skip = False
            continue
        if a == "--workers":
            skip = True
            continue
        if a.startswith("--workers="):
            continue
        out.append(a)
    return out
