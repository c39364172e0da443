"""Benchmark plumbing: the bridge as a subprocess, ROS-side helper processes, raw websocket peers.

Every process gets ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` and the
benchmark's private ``ROS_DOMAIN_ID``; the bridge binds 127.0.0.1 on an
ephemeral port.
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import os
import re
import socket
import ssl
import struct
import sys
from collections import Counter, deque
from collections.abc import Awaitable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from websockets.asyncio.client import ClientConnection, connect

from bench.ports import free_port

ROOT = Path(__file__).resolve().parent.parent
"""The checkout this harness comes from (its scenarios and ROS-side programs run from here)."""
CODE_ROOT = Path(os.environ.get("BENCH_CODE_ROOT") or ROOT).resolve()
"""The checkout whose bridge and client are measured: ``ROOT`` unless ``BENCH_CODE_ROOT``
names another (``python -m bench --compare`` runs this harness on another revision's code)."""
if CODE_ROOT != ROOT and str(CODE_ROOT) not in sys.path:
    # this package is imported already (from ROOT); roslibpy_lite, bridge_server and msgs
    # are imported from CODE_ROOT from here on
    sys.path.insert(0, str(CODE_ROOT))
ROS_SIDE = str(Path(__file__).resolve().parent / "ros_side.py")
READY = re.compile(r"bridge_server listening on wss?://([\d.]+):(\d+)")


def with_code_root(env: dict[str, str], root: Path) -> dict[str, str]:
    """``env`` with ``root`` first on ``PYTHONPATH`` when it is not this checkout."""
    if root != ROOT:
        env["PYTHONPATH"] = os.pathsep.join(p for p in (str(root), env.get("PYTHONPATH", "")) if p)
    return env


def child_env(domain: int) -> dict[str, str]:
    """Environment of every child: loopback DDS, the benchmark's ROS domain, unbuffered output,
    and :data:`CODE_ROOT`'s packages first on the path."""
    env = dict(os.environ)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = env.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    env["ROS_DOMAIN_ID"] = str(domain)
    env["PYTHONUNBUFFERED"] = "1"
    return with_code_root(env, CODE_ROOT)


def _rs_peer() -> Path:
    """``shared/peers/rosbridge_server_rs.sh`` beside this checkout or one of its parents
    (``BENCH_RS_PEER`` names it elsewhere)."""
    named = os.environ.get("BENCH_RS_PEER")
    if named:
        return Path(named)
    for parent in ROOT.parents:
        candidate = parent / "shared" / "peers" / "rosbridge_server_rs.sh"
        if candidate.exists():
            return candidate
    return ROOT.parent / "shared" / "peers" / "rosbridge_server_rs.sh"


RS_PEER = _rs_peer()
"""Runs rosbridge_server_rs (Rust) on our venv's wheels (read its header)."""

_tls_trust: list[ssl.SSLContext] = []


def trust_tls(context: ssl.SSLContext) -> None:
    """Make ``context`` the client TLS context of wss:// bench bridges (the tls scenario)."""
    _tls_trust[:] = [context]


def client_ssl(url: str) -> ssl.SSLContext | None:
    """The client TLS context for a wss:// URL of a bench bridge (``None`` for ws://)."""
    if not url.startswith("wss:"):
        return None
    if not _tls_trust:
        raise RuntimeError("no TLS bridge was set up (run the tls scenario)")
    return _tls_trust[0]


class Bridge:
    """``python -m bridge_server`` on 127.0.0.1, port 0; ``url`` and ``pid`` once started.

    With ``peer="rs"`` it is rosbridge_server_rs instead (:data:`RS_PEER`; no rosapi), for
    side-by-side figures; ``args`` and ``root`` then do not apply.
    """

    def __init__(
        self, domain: int, args: list[str] | None = None, root: str | None = None,
        peer: str = "ours", module: str = "bridge_server", ready: re.Pattern[str] = READY,
    ) -> None:
        """``module``/``ready``: another of our servers (``bridge_server.zenoh.relay``) and
        its ready line (the port is its second group, if it has one)."""
        self.domain = domain
        self.module = module
        self.ready = ready
        self.args = list(args or [])
        self.root = Path(root).resolve() if root else CODE_ROOT
        self.peer = peer
        self.proc: asyncio.subprocess.Process | None = None
        self.port = 0
        self.lines: deque[str] = deque(maxlen=200)
        self.counting: dict[str, str] = {}
        """What to count in its output: a label and the text of the lines it counts."""
        self.counted: Counter[str] = Counter()
        """Lines of its output so far with each label's text in them (:attr:`counting`)."""
        self._drain: asyncio.Task[None] | None = None

    @property
    def url(self) -> str:
        """The websocket URL (wss:// when the bridge serves TLS)."""
        scheme = "wss" if "--certfile" in self.args else "ws"
        return f"{scheme}://127.0.0.1:{self.port}"

    @property
    def pid(self) -> int:
        """The bridge's process id (for psutil and py-spy)."""
        assert self.proc is not None
        return self.proc.pid

    async def start(self, timeout: float = 30.0) -> Bridge:
        """Start the bridge and wait for its ready line."""
        if self.peer == "rs":
            return await self._start_rs(timeout + 60)  # the first start downloads the wheel
        self.proc = await asyncio.create_subprocess_exec(
            sys.executable, "-m", self.module, "--host", "127.0.0.1", "--port", "0",
            *self.args,
            cwd=self.root, env=self._env(), stdin=asyncio.subprocess.DEVNULL,
            stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.STDOUT,
        )
        assert self.proc.stdout is not None

        async def first_line() -> None:
            assert self.proc is not None and self.proc.stdout is not None
            while True:
                raw = await self.proc.stdout.readline()
                if not raw:
                    raise RuntimeError("bridge exited before listening:\n" + "\n".join(self.lines))
                line = raw.decode(errors="replace").rstrip()
                self.lines.append(line)
                m = self.ready.search(line)
                if m:
                    self.port = int(m.group(2)) if m.re.groups >= 2 else 0
                    return

        await asyncio.wait_for(first_line(), timeout)
        self._drain = asyncio.create_task(self._pump())
        return self

    async def _start_rs(self, timeout: float) -> Bridge:
        """Start rosbridge_server_rs on a free port; ready once the port accepts."""
        self.port = free_port()
        self.proc = await asyncio.create_subprocess_exec(
            "bash", str(RS_PEER), str(self.port), cwd=ROOT, env=child_env(self.domain),
            stdin=asyncio.subprocess.DEVNULL, stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.STDOUT,
        )
        self._drain = asyncio.create_task(self._pump())
        deadline = asyncio.get_running_loop().time() + timeout
        while True:
            try:
                _, writer = await asyncio.open_connection("127.0.0.1", self.port)
                writer.close()
                return self
            except OSError:
                if self.proc.returncode is not None:
                    raise RuntimeError("rosbridge_server_rs exited:\n" + "\n".join(self.lines)) from None
                if asyncio.get_running_loop().time() > deadline:
                    raise RuntimeError("rosbridge_server_rs did not listen in time") from None
                await asyncio.sleep(0.1)

    def _env(self) -> dict[str, str]:
        # import bridge_server (and its siblings) from that checkout
        return with_code_root(child_env(self.domain), self.root)

    async def _pump(self) -> None:
        assert self.proc is not None and self.proc.stdout is not None
        while True:
            raw = await self.proc.stdout.readline()
            if not raw:
                return
            line = raw.decode(errors="replace").rstrip()
            self.lines.append(line)
            for label, text in self.counting.items():
                if text in line:
                    self.counted[label] += 1

    async def stop(self) -> None:
        """SIGTERM, then kill if it lingers."""
        if self.proc is None:
            return
        if self.proc.returncode is None:
            self.proc.terminate()
            try:
                await asyncio.wait_for(self.proc.wait(), 5)
            except TimeoutError:
                self.proc.kill()
                await self.proc.wait()
        if self._drain is not None:
            self._drain.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._drain


EVENT_LINE_LIMIT = 64 << 20
"""Longest event line a ROS side may print: an image subscriber's ``done`` lists every frame's
arrival time (about 200 kB for 10 s at 2,000 frames a second, past asyncio's 64 KiB default)."""


class RosSide:
    """A ``bench/ros_side.py`` process; its JSON event lines are read as they come."""

    script = ROS_SIDE
    """The ROS-side program (a subclass may run another one)."""

    def __init__(self, domain: int, *args: str) -> None:
        self.domain = domain
        self.args = list(args)
        self.proc: asyncio.subprocess.Process | None = None
        self.events: asyncio.Queue[dict[str, Any]] = asyncio.Queue()
        self.other: deque[str] = deque(maxlen=50)
        self._reader: asyncio.Task[None] | None = None

    async def start(self) -> RosSide:
        """Start the process (keep stdin open: ``serve`` stops when it closes)."""
        self.proc = await asyncio.create_subprocess_exec(
            sys.executable, self.script, *self.args, cwd=ROOT, env=child_env(self.domain),
            stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.STDOUT,
            limit=EVENT_LINE_LIMIT,
        )
        self._reader = asyncio.create_task(self._read())
        return self

    async def _read(self) -> None:
        assert self.proc is not None and self.proc.stdout is not None
        while True:
            raw = await self.proc.stdout.readline()
            if not raw:
                await self.events.put({"event": "exit"})
                return
            line = raw.decode(errors="replace").strip()
            if line.startswith("{"):
                with contextlib.suppress(ValueError):
                    await self.events.put(json.loads(line))
                    continue
            self.other.append(line)

    async def event(self, name: str, timeout: float = 30.0) -> dict[str, Any]:
        """Await the next event called ``name`` (an ``error`` or exit raises)."""
        async def get() -> dict[str, Any]:
            while True:
                ev = await self.events.get()
                if ev.get("event") == name:
                    return ev
                if ev.get("event") in ("error", "exit"):
                    raise RuntimeError(
                        f"ros_side {self.args[0]} failed waiting for {name}: {ev}\n"
                        + "\n".join(self.other)
                    )

        return await asyncio.wait_for(get(), timeout)

    async def close(self) -> None:
        """Close stdin, wait a moment, then kill."""
        if self.proc is None:
            return
        if self.proc.stdin is not None:
            with contextlib.suppress(Exception):
                self.proc.stdin.close()
        try:
            await asyncio.wait_for(self.proc.wait(), 5)
        except TimeoutError:
            self.proc.kill()
            await self.proc.wait()
        if self._reader is not None:
            self._reader.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._reader


@dataclass
class Ctx:
    """Options shared by the scenarios."""

    duration: float
    quick: bool
    domain: int
    profile: bool
    ros_executor: str = "events"
    bridge_root: str | None = None
    bridge_args: list[str] = field(default_factory=list)
    peer: str = "ours"

    def bridge(self) -> Bridge:
        """A new (not yet started) bridge for one scenario (``--peer``: ours or rs)."""
        return Bridge(self.domain, self.bridge_args, self.bridge_root, self.peer)

    def ros(self, *args: str) -> RosSide:
        """A new (not yet started) ROS-side process."""
        return RosSide(self.domain, *args, "--executor", self.ros_executor)


def percentile(values: list[float], q: float) -> float:
    """The ``q`` quantile (0..1) by nearest rank; NaN for no values."""
    if not values:
        return float("nan")
    s = sorted(values)
    k = min(len(s) - 1, max(0, round(q * (len(s) - 1))))
    return s[k]


class StalledClient:
    """A raw TCP websocket client: handshake, send ops, then never read again.

    Its receive buffer is made small, so the bridge's socket fills quickly.
    """

    def __init__(self, port: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        self.sock.settimeout(10)
        self.sock.connect(("127.0.0.1", port))
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall(
            (
                "GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\n"
                f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                "Sec-WebSocket-Version: 13\r\n\r\n"
            ).encode()
        )
        reply = b""
        while b"\r\n\r\n" not in reply:
            chunk = self.sock.recv(1)
            if not chunk:
                raise ConnectionError("bridge closed during the handshake")
            reply += chunk
        if b" 101 " not in reply.split(b"\r\n", 1)[0]:
            raise ConnectionError(f"handshake refused: {reply[:80]!r}")

    def send(self, op: dict[str, Any]) -> None:
        """Send one op as a masked text frame."""
        payload = json.dumps(op).encode()
        mask = os.urandom(4)
        n = len(payload)
        if n < 126:
            head = struct.pack("!BB", 0x81, 0x80 | n)
        elif n < 65536:
            head = struct.pack("!BBH", 0x81, 0x80 | 126, n)
        else:
            head = struct.pack("!BBQ", 0x81, 0x80 | 127, n)
        masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
        self.sock.sendall(head + mask + masked)

    def close(self) -> None:
        """Drop the connection without a closing handshake."""
        with contextlib.suppress(OSError):
            self.sock.close()


async def ws_open(url: str) -> ClientConnection:
    """A raw websockets client, no compression, no size limit."""
    return await connect(url, max_size=None, compression=None, open_timeout=10, max_queue=1024,
                         ssl=client_ssl(url))


def send_op(ws: ClientConnection, op: dict[str, Any]) -> Awaitable[None]:
    """Send one op as JSON text."""
    return ws.send(json.dumps(op))


async def close_clients(sockets: list[ClientConnection], readers: list[asyncio.Task[None]]) -> None:
    """Close a scenario's websocket clients, then cancel the tasks that read them."""
    for ws in sockets:
        await ws.close()
    for task in readers:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


IMAGE_PUBLISHER = ("--kind", "image", "--rate", "0", "--depth", "5", "--settle", "0.3",
                   "--linger", "0.5")
"""The one image publisher of every image figure (each encoding, every server, the ROS
ceiling): 640x480 rgb8 frames numbered in ``header.frame_id``, as fast as rclpy publishes
them for the scenario's duration, history depth 5."""


_FRAME_SEQ = re.compile(rb"(\d+) \d{6,}")
"""``header.frame_id`` of a bench image, ``"<seq> <monotonic ns>"``: the only digits-space-digits
in a publish frame's first bytes, whichever the encoding (JSON text, CBOR, CDR in cbor-raw)."""


FRAME_SEQ_BYTES = 512
"""A bench image frame's first bytes, where :func:`frame_seq` finds its number."""


def frame_seq(frame: str | bytes) -> int | None:
    """The sequence number of a bench image's publish frame (``None`` if it has none); only
    its first :data:`FRAME_SEQ_BYTES` are read."""
    head = frame[:FRAME_SEQ_BYTES]
    m = _FRAME_SEQ.search(head.encode() if isinstance(head, str) else head)
    return int(m.group(1)) if m else None


IMAGE_GRACE = 1.0
"""Seconds after the publisher's last frame in which frames still count as delivered (a
server that holds frames back longer, as rosbridge_server_rs does under a full-speed image
stream, delivers them outside the measured time)."""
