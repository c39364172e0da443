"""Run a stock client (roslibpy or roslib for Node) as a child process and talk to it.

Both driver programs (``roslibpy_peer.py`` and ``node/peer.mjs``) speak the same
line protocol: the test writes JSON commands with a ``seq`` number on the
child's stdin; the child answers each with ``{"seq", "ok", "value"|"error"}``
and prints ``{"event": ...}`` lines for what the bridge pushes to it. Every
wait here has a deadline, and the child is killed if it does not leave when
told, so no test can hang on a stuck peer.
"""

from __future__ import annotations

import itertools
import json
import shutil
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import BridgeProcess, ros_env

PEERS = Path(__file__).resolve().parent
NODE_DIR = PEERS / "node"


class PeerError(AssertionError):
    """The stock client reported that a command failed (the text is its own error)."""


class PeerProcess:
    """A stock rosbridge client in a child process, obeying JSON line commands."""

    def __init__(
        self, name: str, argv: Sequence[str], cwd: Path, env: dict[str, str] | None = None
    ) -> None:
        self.name = name
        self.argv = list(argv)
        self.cwd = cwd
        self.env = dict(env or {})
        self.proc: subprocess.Popen[str] | None = None
        self.events: list[dict[str, Any]] = []
        self.replies: dict[int, dict[str, Any]] = {}
        self.stderr: list[str] = []
        self.noise: list[str] = []
        self._cond = threading.Condition()
        self._seq = itertools.count(1)
        self._eof = False
        self._readers: list[threading.Thread] = []
        self.info: dict[str, Any] = {}
        #: Index of the first event that belongs to the current test (a peer may be shared).
        self.since = 0
        self.stderr_since = 0  # the same for stderr lines
        #: The bridge this client talks to, if known: the end of its log is in diagnostics.
        self.bridge: BridgeProcess | None = None

    def start(self, timeout: float = 20.0) -> PeerProcess:
        """Start the child and wait until it says it is connected."""
        self.proc = subprocess.Popen(
            self.argv, cwd=self.cwd, env=ros_env(**self.env), stdin=subprocess.PIPE,
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, bufsize=1,
        )
        self._readers = [
            threading.Thread(target=self._read_stdout, daemon=True),
            threading.Thread(target=self._read_stderr, daemon=True),
        ]
        for reader in self._readers:
            reader.start()
        ready = self.wait_event(
            lambda e: e.get("event") in ("ready", "connect_failed"), timeout, "connection"
        )
        if ready["event"] != "ready":
            raise AssertionError(f"{self.name} could not connect: {ready}\n{self.diagnostics()}")
        self.info = ready
        return self

    def _read_stdout(self) -> None:
        assert self.proc is not None and self.proc.stdout is not None
        for line in self.proc.stdout:
            try:
                obj = json.loads(line)
            except ValueError:
                obj = None
            with self._cond:
                if not isinstance(obj, dict):
                    self.noise.append(line.rstrip("\n"))
                elif "seq" in obj and "event" not in obj:
                    self.replies[int(obj["seq"])] = obj
                else:
                    self.events.append(obj)
                self._cond.notify_all()
        with self._cond:
            self._eof = True
            self._cond.notify_all()

    def _read_stderr(self) -> None:
        assert self.proc is not None and self.proc.stderr is not None
        for line in self.proc.stderr:
            with self._cond:
                self.stderr.append(line.rstrip("\n"))

    def diagnostics(self) -> str:
        """What the child printed during this test besides replies: for failure messages.

        Only this test's stderr: roslibpy prints a traceback for every ``status``
        op (it has no handler for them), so a shared peer's earlier tests would
        otherwise look like refusals of this test's ops.
        """
        with self._cond:
            err = "\n".join(self.stderr[self.stderr_since:][-40:])
            noise = "\n".join(self.noise[-20:])
            events = json.dumps(self.events[self.since:][-10:], default=str)[:2000]
        text = f"--- {self.name} stderr:\n{err}\n--- stdout noise:\n{noise}\n--- last events: {events}"
        if self.bridge is not None:  # what the bridge made of this client's ops
            text += "\n--- bridge log:\n" + "\n".join(self.bridge.lines[-30:])
        return text

    def send(self, cmd: str, **params: Any) -> int:
        """Send one command without waiting; returns its sequence number."""
        assert self.proc is not None and self.proc.stdin is not None
        seq = next(self._seq)
        self.proc.stdin.write(json.dumps({"seq": seq, "cmd": cmd, **params}) + "\n")
        self.proc.stdin.flush()
        return seq

    def reply(self, seq: int, timeout: float = 10.0) -> dict[str, Any]:
        """Wait for the reply to command ``seq``."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while seq not in self.replies:
                left = deadline - time.monotonic()
                if self._eof:
                    raise AssertionError(f"{self.name} exited before answering\n{self.diagnostics()}")
                if left <= 0:
                    raise AssertionError(
                        f"{self.name} gave no answer to command {seq} in {timeout} s\n"
                        + self.diagnostics()
                    )
                self._cond.wait(left)
            return self.replies.pop(seq)

    def request(self, cmd: str, timeout: float = 10.0, **params: Any) -> Any:
        """Run a command and return its value; a failure reported by the client raises PeerError."""
        answer = self.reply(self.send(cmd, **params), timeout)
        if not answer.get("ok"):
            raise PeerError(f"{self.name} {cmd} failed: {answer.get('error')}")
        return answer.get("value")

    @property
    def alive(self) -> bool:
        """Whether the child is still running and connected to its output."""
        return self.proc is not None and self.proc.poll() is None and not self._eof

    def begin_test(self) -> None:
        """Start a new test on this peer: earlier events are no longer looked at."""
        with self._cond:
            self.since = len(self.events)
            self.stderr_since = len(self.stderr)

    def new_events(self) -> list[dict[str, Any]]:
        """The events that arrived since the current test began."""
        with self._cond:
            return list(self.events[self.since:])

    def wait_event(
        self, predicate: Callable[[dict[str, Any]], bool], timeout: float = 10.0,
        what: str = "event",
    ) -> dict[str, Any]:
        """Wait for an event of the current test that satisfies ``predicate``."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                for event in self.events[self.since:]:
                    if predicate(event):
                        return event
                left = deadline - time.monotonic()
                if left <= 0 or self._eof:
                    raise AssertionError(
                        f"{self.name}: no {what} within {timeout} s\n{self.diagnostics()}"
                    )
                self._cond.wait(left)

    def close(self, timeout: float = 10.0) -> int:
        """Tell the child to disconnect and exit; kill it if it does not."""
        if self.proc is None:
            return 0
        if self.proc.poll() is None:
            try:
                assert self.proc.stdin is not None
                self.proc.stdin.write(json.dumps({"cmd": "close"}) + "\n")
                self.proc.stdin.close()
            except OSError:
                pass
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        else:
            assert self.proc.stdin is not None
            self.proc.stdin.close()
        for reader in self._readers:
            reader.join(timeout)
        for stream in (self.proc.stdout, self.proc.stderr):
            if stream is not None:
                stream.close()
        return self.proc.returncode


def _node_argv(url: str, native_websocket: bool, script: str = "peer.mjs",
               package: str = "roslib") -> list[str]:
    """The command line of a Node driver; skips without node, fails without its modules."""
    node = shutil.which("node")
    if node is None:
        pytest.skip(f"node is not on PATH: the {package} (npm) peer tests need Node.js 20+")
    if not (NODE_DIR / "node_modules" / package / "package.json").is_file():
        pytest.fail(
            f"tests/peers/node/node_modules has no {package}: run scripts/setup.sh "
            "(or `npm ci` in tests/peers/node)",
            pytrace=False,
        )
    flags = ["--experimental-websocket"] if native_websocket else []
    return [node, *flags, str(NODE_DIR / script), url]


def foxglove_peer(url: str, bridge: BridgeProcess | None = None) -> PeerProcess:
    """A started Foxglove client (``@foxglove/ws-protocol`` in Node) on ``url``."""
    argv = _node_argv(url, False, "foxglove_peer.mjs", "@foxglove/ws-protocol")
    peer = PeerProcess("foxglove", argv, PEERS)
    peer.bridge = bridge
    try:
        return peer.start()
    except BaseException:
        peer.close()
        raise


class PeerPool:
    """Stock-client processes connected to one bridge, started on demand and reused.

    Starting a client costs about half a second (a second on a busy machine);
    the tests use unique topic and service names, so one process per kind can
    serve a whole module. A process that died is replaced by a fresh one.
    """

    def __init__(self, bridge: BridgeProcess) -> None:
        self.bridge = bridge
        self.peers: dict[tuple[str, bool], PeerProcess] = {}

    def start(self, kind: str, native_websocket: bool = False) -> PeerProcess:
        """Start a new client process of ``kind`` (not shared; the caller closes it).

        Kinds: "roslibpy" (its default Twisted transport), "roslibpy-asyncio" (its
        opt-in asyncio transport), "roslib" (Node; ``native_websocket`` picks Node's
        own WebSocket instead of the ``ws`` package), "foxglove" (``@foxglove/ws-protocol``
        in Node).
        """
        if kind == "foxglove":
            return foxglove_peer(self.bridge.url, self.bridge)
        env: dict[str, str] = {}
        if kind in ("roslibpy", "roslibpy-asyncio"):
            argv = [sys.executable, str(PEERS / "roslibpy_peer.py"), "127.0.0.1",
                    str(self.bridge.port)]
            name = kind
            env["ROSLIBPY_TRANSPORT"] = "asyncio" if kind == "roslibpy-asyncio" else "twisted"
        elif kind == "roslib":
            argv = _node_argv(self.bridge.url, native_websocket)
            name = "roslib-native" if native_websocket else "roslib-ws"
        else:
            raise ValueError(kind)
        peer = PeerProcess(name, argv, PEERS, env)
        peer.bridge = self.bridge  # its log goes into failure messages
        try:
            return peer.start()
        except BaseException:
            peer.close()
            raise

    def get(self, kind: str, native_websocket: bool = False) -> PeerProcess:
        """The shared live client of ``kind``, (re)started if needed, ready for a new test."""
        key = (kind, native_websocket)
        peer = self.peers.get(key)
        if peer is None or not peer.alive:
            if peer is not None:
                peer.close()
            peer = self.peers[key] = self.start(kind, native_websocket)
        peer.begin_test()
        return peer

    def close(self) -> None:
        """Close every client this pool started."""
        for peer in self.peers.values():
            peer.close()
        self.peers.clear()
