"""The fleet benchmark's processes: JSON-speaking children, HAProxy, and what they cost.

- :class:`Child`: a Python child (``bench.simrobot``, ``bench.fleetview``, ``bench.zrouter``)
  or a Node one (``bench/fleetview.mjs``) that prints JSON lines and takes JSON commands on
  stdin; other lines are kept for errors.
- :func:`haproxy_config` / :class:`Balancer`: HAProxy in TCP mode before the relays, with
  the configuration ``deploy/haproxy/haproxy.cfg`` shows (the benchmark writes its own with
  the relays' ephemeral ports).
- :class:`Usage`: RSS and CPU of a set of processes over a window.
"""

from __future__ import annotations

import asyncio
import contextlib
import csv
import io
import json
import os
import shutil
import sys
import tempfile
import time
import urllib.request
from collections import deque
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from bench.harness import ROOT, child_env
from bench.profiler import py_spy

__all__ = ["CHECK_TIMEOUT", "NODE_MODULES", "Balancer", "Child", "Usage", "get", "haproxy_config",
           "json_lines", "node_viewers"]

CHECK_TIMEOUT = "3s"
"""How long HAProxy waits for a relay's ``/readyz`` answer (its default, the check interval,
marked a relay whose event loop stalled half a second as down)."""


NODE_MODULES = ROOT / "tests" / "peers" / "node" / "node_modules"
"""Where ``scripts/setup.sh`` installs the stock roslib client, and with it ``ws``."""


def node_viewers() -> bool:
    """Whether Node and its ``ws`` package are here, for ``bench/fleetview.mjs``."""
    return shutil.which("node") is not None and (NODE_MODULES / "ws").is_dir()


def json_lines() -> Callable[[dict[str, Any]], None]:
    """(In a Python child, at its start.) What writes its JSON lines: standard output as it
    was, while descriptor 1 itself goes to standard error from then on, as :class:`Child`
    reads them apart. Zenoh writes its log to descriptor 1 from its own threads, and Python
    logs from other threads than the loop's (the putting threads, Zenoh's callbacks); a line
    longer than a pipe takes in one write (4 KiB: the ``stats`` of a process of 250 robots)
    can be cut by one of theirs in the middle, and its reader then no longer knows it for an
    answer. After a router's restart, when 250 sessions log at once, a robot process whose
    loop was turning (``gdb``) went on "not answering" for minutes."""
    sys.stdout.flush()
    out = os.fdopen(os.dup(1), "w", buffering=1, encoding="utf-8")
    os.dup2(2, 1)

    def say(obj: dict[str, Any]) -> None:
        out.write(json.dumps(obj) + "\n")
        out.flush()

    return say


class Child:
    """A child process printing JSON lines (see the module's text): ``argv`` a Python
    module and its arguments, or a ``.mjs`` script's path (from the checkout's root) and
    its arguments, run by Node."""

    def __init__(self, argv: list[str], domain: int, name: str) -> None:
        self.argv = argv
        self.domain = domain
        self.name = name
        self.proc: asyncio.subprocess.Process | None = None
        self.events: asyncio.Queue[dict[str, Any]] = asyncio.Queue()
        self.lines: deque[str] = deque(maxlen=50)
        self._reader: asyncio.Task[None] | None = None
        self._said: asyncio.Task[None] | None = None

    @property
    def pid(self) -> int:
        """The child's process id."""
        assert self.proc is not None
        return self.proc.pid

    @property
    def node(self) -> bool:
        """Whether it is a Node script (else a Python module)."""
        return self.argv[0].endswith(".mjs")

    async def start(self) -> Child:
        """Start the child (a Python module, or a Node script)."""
        env = child_env(self.domain)
        if self.node:
            command = ["node", *self.argv]
            env["NODE_PATH"] = str(NODE_MODULES)
        else:
            command = [sys.executable, "-m", *self.argv]
        self.proc = await asyncio.create_subprocess_exec(
            *command, cwd=ROOT, env=env,
            stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.PIPE, limit=2**26)
        self._reader = asyncio.create_task(self._read())
        self._said = asyncio.create_task(self._read_log())
        return self

    async def _read_log(self) -> None:
        """Its standard error (its log, and Zenoh's in a Python child: :func:`json_lines`),
        kept for errors."""
        assert self.proc is not None and self.proc.stderr is not None
        while raw := await self.proc.stderr.readline():
            self.lines.append(raw.decode(errors="replace").rstrip())

    async def _read(self) -> None:
        assert self.proc is not None and self.proc.stdout is not None
        while raw := await self.proc.stdout.readline():
            line = raw.decode(errors="replace").rstrip()
            try:
                obj = json.loads(line)
            except ValueError:
                obj = None
            if isinstance(obj, dict):
                self.events.put_nowait(obj)
            else:
                self.lines.append(line)
        self.events.put_nowait({"event": "exited", "output": "\n".join(self.lines)})

    async def event(self, timeout: float = 120.0) -> dict[str, Any]:
        """The next JSON line (``RuntimeError`` if the child exited or went silent)."""
        try:
            got = await asyncio.wait_for(self.events.get(), timeout)
        except TimeoutError:
            raise RuntimeError(f"{self.name}: no answer in {timeout:g} s:\n"
                               + "\n".join(self.lines) + await self._stacks()) from None
        if got.get("event") == "exited":
            raise RuntimeError(f"{self.name} exited:\n{got['output']}")
        return got

    async def _stacks(self) -> str:
        """Where a Python child's threads are, to say why it went silent: ``py-spy dump
        --native`` (if installed: a loop stalled, or waiting for the interpreter's lock under
        a Python frame that looks idle), and every thread's native stack by ``gdb`` (if
        installed: Zenoh's threads, which have no Python frames) written to a file named
        here."""
        if self.proc is None or self.node:
            return ""
        pid = str(self.proc.pid)
        said = ""
        spy = py_spy()
        if spy is not None:
            said += "\npy-spy dump:\n" + await _output(spy, "dump", "--native", "--pid", pid)
        gdb = shutil.which("gdb")
        if gdb is not None:
            path = Path(tempfile.gettempdir()) / f"bench-{self.name}-{pid}-threads.txt"
            path.write_text(await _output(gdb, "-p", pid, "-batch", "-ex",
                                          "thread apply all bt"))
            said += f"\nevery thread's stack (gdb): {path}"
        return said

    async def command(self, cmd: dict[str, Any], timeout: float = 120.0) -> dict[str, Any]:
        """Send one command and return its answer."""
        assert self.proc is not None and self.proc.stdin is not None
        try:
            self.proc.stdin.write(json.dumps(cmd).encode() + b"\n")
            await self.proc.stdin.drain()
        except (ConnectionResetError, BrokenPipeError):  # it ended: say which, and how
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self.proc.wait(), 5)
            raise RuntimeError(f"{self.name} gone (exit code {self.proc.returncode}):\n"
                               + "\n".join(self.lines)) from None
        return await self.event(timeout)

    def kill(self) -> None:
        """SIGKILL (a crash)."""
        if self.proc is not None and self.proc.returncode is None:
            self.proc.kill()

    async def stop(self) -> None:
        """Close stdin (the child ends), then SIGTERM, then SIGKILL."""
        if self.proc is None:
            return
        if self.proc.stdin is not None and not self.proc.stdin.is_closing():
            self.proc.stdin.close()
        for step in (lambda p: None, lambda p: p.terminate(), lambda p: p.kill()):
            if self.proc.returncode is not None:
                break
            with contextlib.suppress(ProcessLookupError):
                step(self.proc)
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self.proc.wait(), 10)
        for task in (self._reader, self._said):
            if task is not None:
                task.cancel()


def get(url: str, timeout: float) -> bytes:
    """The body at ``url`` (``OSError`` or ``http.client.HTTPException`` if it fails)."""
    with urllib.request.urlopen(url, timeout=timeout) as r:
        return bytes(r.read())


async def _output(*argv: str) -> str:
    """What ``argv`` printed (standard output and error), as text."""
    proc = await asyncio.create_subprocess_exec(*argv, stdout=asyncio.subprocess.PIPE,
                                                stderr=asyncio.subprocess.STDOUT)
    out, _ = await proc.communicate()
    return out.decode(errors="replace")


def haproxy_config(port: int, relays: Iterable[int], stats_port: int | None = None) -> str:
    """HAProxy in TCP mode on ``port`` (at most 9,900 connections: two descriptors each,
    within this machine's 20,000) before the relays on ``relays`` (loopback): the least
    busy relay takes each new connection; a relay whose ``/readyz`` does not answer 200
    within :data:`CHECK_TIMEOUT` three times in a row (asked every second: it is down, or
    has not reached its router) gets no new connections. Its open connections are not cut:
    a relay that died closes them itself (its clients dial again and land on another), and
    one that is only busy (opening many robots at once, a thousand viewers arriving) keeps
    serving them; cutting those (``on-marked-down shutdown-sessions``, with a 500 ms check)
    turned a one-second stall into every viewer dialing again at once, which stalled the
    relay longer: at 100 robots and 1,000 viewers the relay ended with no viewer at all.
    Long-lived websockets are not timed out."""
    servers = "\n".join(f"    server relay{i} 127.0.0.1:{p} check inter 1s fall 3 rise 2"
                         for i, p in enumerate(relays))
    stats = (f"\nfrontend stats\n    mode http\n    bind 127.0.0.1:{stats_port}\n"
             "    stats enable\n    stats uri /\n" if stats_port else "")
    return f"""global
    maxconn 9900

defaults
    mode tcp
    timeout connect 2s
    timeout check {CHECK_TIMEOUT}
    timeout client 1h
    timeout server 1h
    timeout tunnel 1h
    retries 2
    option redispatch

frontend viewers
    bind 127.0.0.1:{port}
    default_backend relays

backend relays
    balance leastconn
    option httpchk GET /readyz
    http-check expect status 200
{servers}
{stats}"""


class Balancer:
    """HAProxy (Debian's ``haproxy``) started in the foreground with a written config."""

    def __init__(self, config: str, folder: Path, port: int, stats_port: int | None = None
                 ) -> None:
        """``stats_port``: the port of its statistics page, if ``config`` has one
        (:func:`haproxy_config`'s ``stats_port``), for :meth:`counts`."""
        self.path = folder / "haproxy.cfg"
        self.path.write_text(config)
        self.port = port
        self.stats_port = stats_port
        self.proc: asyncio.subprocess.Process | None = None

    def counts(self, timeout: float = 10.0) -> dict[str, Any]:
        """What it did with the connections it took (from its statistics page, CSV): how many
        it took (``sessions``), how many it passed to each relay (by its name in the config,
        ``relay0``...) with the relay's health (``status``: ``UP`` or ``DOWN``;
        ``went_down``: times its checks marked it down; ``down_s``: seconds it was down), and
        how many reached no relay (``to_no_relay``: taken while every relay was down, or
        refused by all it tried: the backend's connection errors). A connection one relay
        refused and the balancer then passed to another counts for both relays."""
        assert self.stats_port is not None, "started without a statistics page"
        text = get(f"http://127.0.0.1:{self.stats_port}/;csv", timeout).decode()
        rows = list(csv.DictReader(io.StringIO(text.lstrip("# "))))
        front = next(r for r in rows if r["svname"] == "FRONTEND" and r["pxname"] == "viewers")
        relays = {r["svname"]: {"sessions": int(r["stot"] or 0), "status": r["status"],
                                "went_down": int(r["chkdown"] or 0),
                                "down_s": int(r["downtime"] or 0)}
                  for r in rows if r["pxname"] == "relays" and r["svname"] != "BACKEND"}
        back = next(r for r in rows if r["svname"] == "BACKEND" and r["pxname"] == "relays")
        return {"sessions": int(front["stot"] or 0), "relays": relays,
                "to_no_relay": int(back["econ"] or 0)}

    async def start(self, timeout: float = 20.0) -> Balancer:
        """Start it and wait until its port accepts."""
        exe = shutil.which("haproxy") or "/usr/sbin/haproxy"
        if not Path(exe).exists():
            raise RuntimeError("haproxy is not installed (apt-get install haproxy; "
                               "scripts/setup.sh does it)")
        self.proc = await asyncio.create_subprocess_exec(
            exe, "-db", "-f", str(self.path), stdin=asyncio.subprocess.DEVNULL,
            stdout=asyncio.subprocess.DEVNULL, stderr=asyncio.subprocess.DEVNULL)
        deadline = time.monotonic() + timeout
        while True:
            try:
                _, w = await asyncio.open_connection("127.0.0.1", self.port)
                w.close()
                return self
            except OSError:
                if self.proc.returncode is not None or time.monotonic() > deadline:
                    raise RuntimeError(f"haproxy did not listen on {self.port}") from None
                await asyncio.sleep(0.1)

    async def stop(self) -> None:
        """SIGTERM and wait."""
        if self.proc is not None and self.proc.returncode is None:
            self.proc.terminate()
            await self.proc.wait()


class Usage:
    """RSS and CPU of named processes: :meth:`sample` now, :meth:`since` a window."""

    def __init__(self, pids: Callable[[], dict[str, list[int]]]) -> None:
        self.pids = pids
        self._t0 = 0.0
        self._cpu0: dict[str, float] = {}

    def _read(self) -> tuple[dict[str, float], dict[str, float]]:
        import psutil

        rss: dict[str, float] = {}
        cpu: dict[str, float] = {}
        for group, pids in self.pids().items():
            rss[group] = cpu[group] = 0.0
            for pid in pids:
                with contextlib.suppress(psutil.Error):
                    p = psutil.Process(pid)
                    t = p.cpu_times()
                    rss[group] += p.memory_info().rss
                    cpu[group] += t.user + t.system
        return rss, cpu

    def start(self) -> None:
        """Begin a window."""
        self._t0 = time.monotonic()
        self._cpu0 = self._read()[1]

    def since(self) -> dict[str, dict[str, float]]:
        """Each group's RSS (MiB) now and CPU (% of one core) since :meth:`start`."""
        rss, cpu = self._read()
        wall = max(time.monotonic() - self._t0, 1e-9)
        return {g: {"rss_mib": round(rss[g] / 2**20, 1),
                    "cpu_pct": round(100 * (cpu[g] - self._cpu0.get(g, 0.0)) / wall, 1)}
                for g in rss}
