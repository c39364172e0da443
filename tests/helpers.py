"""Test helpers shared by every test package: bridge processes, rclpy, waiting; the peers
that send ops (raw websockets, memory links) are in :mod:`tests.op_peer`, re-exported here.

The fixtures in ``tests/conftest.py`` are thin wrappers around these.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import traceback
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from bench.ports import free_port as _free_port
from tests.op_peer import (
    OpPeer,
    WireClient,
    error_text,
    open_wire,
    rosapi,
    rosapi_until,
    roundtrip,
    send_until_heard,
    send_until_heard_sync,
    sender_and_bystander,
    still_working,
)

__all__ = [  # the peers of tests.op_peer re-exported: the suite imports them from here
    "CHROMEDRIVER",
    "CHROMIUM",
    "READY",
    "ROOT",
    "BridgeProcess",
    "OpPeer",
    "WireClient",
    "action_server_answers",
    "async_wait_until",
    "error_text",
    "free_port",
    "headless_chromium",
    "marked_blocks",
    "open_wire",
    "peak_rss",
    "rclpy_action_race",
    "ros_env",
    "ros_image",
    "rosapi",
    "rosapi_until",
    "roundtrip",
    "run_snippet",
    "send_until_heard",
    "send_until_heard_sync",
    "sender_and_bystander",
    "settle_executor",
    "spin_executor",
    "spun_node",
    "still_working",
    "threads_since",
    "wait_until",
]

ROOT = Path(__file__).resolve().parent.parent
READY = re.compile(r"bridge_server listening on wss?://([\d.]+):(\d+)")


def ros_env(**extra: str) -> dict[str, str]:
    """The environment for a child process that may start rclpy: loopback DDS, this run's domain."""
    env = dict(os.environ)
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    env["PYTHONUNBUFFERED"] = "1"
    env.update(extra)
    return env


def free_port() -> int:
    """A TCP port nobody listens on now on 127.0.0.1, and that the kernel will not give a
    ``port=0`` listener or a connection meanwhile (for a program that reports no bound port,
    or a test that must know it first; the same number is free on a namespace's own address
    too): :func:`bench.ports.free_port`."""
    return _free_port()


def ros_image(width: int, height: int, encoding: str, data: bytes, frame_id: str = "") -> Any:
    """An rclpy ``sensor_msgs/msg/Image`` of 3-byte pixels (``rgb8``, ``bgr8``)."""
    from sensor_msgs.msg import Image

    msg = Image(height=height, width=width, encoding=encoding, step=width * 3, data=data)
    msg.header.frame_id = frame_id
    return msg


def threads_since(before: set[threading.Thread]) -> list[str]:
    """The names of the threads alive now that were not in ``before`` (``set(threading.
    enumerate())`` taken earlier). Compare sets, not ``threading.active_count()``: a thread
    an earlier test of the same worker left to end on its own may end meanwhile."""
    return sorted(t.name for t in set(threading.enumerate()) - before)


def wait_until(predicate: Callable[[], Any], timeout: float = 10.0, what: str = "condition") -> Any:
    """Poll ``predicate`` until it is truthy (for ROS graph discovery, which has no event)."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(0.02)


async def async_wait_until(
    predicate: Callable[[], Any], timeout: float = 10.0, what: str = "condition"
) -> Any:
    """The asyncio twin of :func:`wait_until`."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        await asyncio.sleep(0.02)


def marked_blocks(path: Path, tag: str) -> list[tuple[str, str]]:
    """The fenced Python blocks of a Markdown file marked ``<!-- TAG: KIND -->``, as (kind, code)."""
    marked = re.compile(rf"<!-- {tag}: (\w+) -->\n```python\n(.*?)```", re.S)
    return marked.findall(path.read_text())


def run_snippet(code: str, bridge: BridgeProcess | None = None, timeout: float = 60,
                cwd: Path = ROOT) -> str:
    """Run a documentation example as a user would; returns its output (fails on an error).

    With ``bridge``, the example's ``ws://127.0.0.1:9090`` (or ``port=9090``) points at it.
    In another ``cwd`` (where the example's own files are) this checkout is still imported.
    """
    if bridge is not None:
        code = code.replace("ws://127.0.0.1:9090", bridge.url)
        code = code.replace("port=9090", f"port={bridge.port}")
    done = subprocess.run([sys.executable, "-c", code], cwd=cwd, env=ros_env(PYTHONPATH=str(ROOT)),
                          capture_output=True, text=True, timeout=timeout)
    assert done.returncode == 0, done.stdout + done.stderr
    return done.stdout


class BridgeProcess:
    """A ``python -m bridge_server`` child process on 127.0.0.1.

    ``start()`` waits for the ready line; ``port`` stays the same across a
    ``stop()``/``start()`` pair, so clients can reconnect to the same URL.
    Everything the bridge logs is kept in ``lines`` (and echoed on failure).
    """

    def __init__(self, port: int = 0, args: list[str] | None = None,
                 env: dict[str, str] | None = None) -> None:
        self.port = port
        self.args = list(args or [])
        self.env = env or {}
        self.proc: subprocess.Popen[str] | None = None
        self.lines: list[str] = []
        self._cond = threading.Condition()
        self._pump_thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        """The websocket URL of the running bridge."""
        return f"ws://127.0.0.1:{self.port}"

    def start(self, timeout: float = 30.0) -> BridgeProcess:
        """Start the bridge and wait until it listens."""
        assert self.proc is None or self.proc.poll() is not None, "bridge already running"
        cmd = [sys.executable, "-m", "bridge_server", "--host", "127.0.0.1",
               "--port", str(self.port), *self.args]
        self.proc = subprocess.Popen(
            cmd, cwd=ROOT, env=ros_env(**self.env), stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT, text=True, bufsize=1,
        )
        first = len(self.lines)
        self._pump_thread = threading.Thread(target=self._pump, args=(self.proc,), daemon=True)
        self._pump_thread.start()
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                for line in self.lines[first:]:
                    m = READY.search(line)
                    if m:
                        self.port = int(m.group(2))
                        return self
                if self.proc.poll() is not None:
                    raise RuntimeError("bridge exited before it listened:\n" + self.log())
                left = deadline - time.monotonic()
                if left <= 0:
                    self.kill()
                    raise RuntimeError("bridge did not listen in time:\n" + self.log())
                self._cond.wait(left)

    def _pump(self, proc: subprocess.Popen[str]) -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            with self._cond:
                self.lines.append(line.rstrip("\n"))
                self._cond.notify_all()
        proc.stdout.close()
        with self._cond:
            self._cond.notify_all()

    def _reap(self) -> None:
        if self._pump_thread is not None:
            self._pump_thread.join(10)
            self._pump_thread = None

    def wait_for_line(self, pattern: str, timeout: float = 10.0, start: int = 0) -> str:
        """Wait until the bridge logs a line matching ``pattern`` (from line ``start`` on)."""
        rx = re.compile(pattern)
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                for line in self.lines[start:]:
                    if rx.search(line):
                        return line
                left = deadline - time.monotonic()
                if left <= 0:
                    raise AssertionError(f"bridge never logged /{pattern}/:\n" + self.log())
                self._cond.wait(left)

    @property
    def node_name(self) -> str:
        """The bridge's fully qualified ROS node name (from its start-up line)."""
        line = self.wait_for_line(r"ROS node /\S+ on ROS_DOMAIN_ID")
        match = re.search(r"ROS node (/\S+)", line)
        assert match is not None
        return match.group(1)

    def log(self) -> str:
        """Everything the bridge printed so far."""
        with self._cond:
            return "\n".join(self.lines[-200:])

    def stop(self, sig: int = signal.SIGTERM, timeout: float = 10.0) -> int:
        """Signal the bridge and wait for it to exit; returns its exit code."""
        if self.proc is None or self.proc.poll() is not None:
            return self.proc.returncode if self.proc else 0
        self.proc.send_signal(sig)
        try:
            return self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
            raise AssertionError("bridge did not exit on signal:\n" + self.log()) from None
        finally:
            self._reap()

    def kill(self) -> None:
        """Kill the bridge at once (a crash, for fault tests)."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        self._reap()


def action_server_answers(client: Any, every: float = 0.2) -> Callable[[], bool]:
    """A predicate for :func:`wait_until`: ``client``'s action server is matched *and* answers.

    rclpy's ``server_is_ready()`` turns true once requests reach the server, which
    may not have matched the client's reply readers yet; a goal sent then is
    accepted and its answer lost. So, once matched, the predicate asks (every
    ``every`` s until one is answered) for the result of a goal that does not exist,
    which a server answers at once with STATUS_UNKNOWN. (The bridge's own action
    client does the same: ``SharedActionClient.ready``.)
    """
    from rclpy.action.client import ClientGoalHandle
    from unique_identifier_msgs.msg import UUID

    answered = threading.Event()
    last = [0.0]

    def check() -> bool:
        if answered.is_set():
            return True
        if not client.server_is_ready():
            return False
        now = time.monotonic()
        if now - last[0] >= every:
            last[0] = now
            nobody = ClientGoalHandle(client, UUID(uuid=list(os.urandom(16))),  # type: ignore[no-untyped-call]
                                      client._action_type.Impl.SendGoalService.Response())
            client._get_result_async(nobody).add_done_callback(lambda _f: answered.set())
        return False

    return check


def rclpy_action_race(exc: BaseException) -> bool:
    """Whether ``exc`` is one of rclpy's own known races in a test's peer node.

    Made or destroyed by a test while the executor waits, an rclpy action client or
    server fails in ``is_ready``/``take_data`` (ros2/rclpy#1455, #1589); it stalls
    nothing but that action end when the end has a callback group of its own. A
    service (a node's parameter services too) answering a caller that has gone
    fails inside rclpy's ``send_response``, and so does an action server answering
    a caller whose reply reader DDS has not matched yet (the bridge probes a new
    server exactly for that). None of it says anything about the bridge.
    """
    frames = traceback.extract_tb(exc.__traceback__)
    return any(
        (f.filename.endswith(("rclpy/action/client.py", "rclpy/action/server.py"))
         and f.name in ("is_ready", "take_data", "add_to_wait_set", "get_num_entities"))
        or (f.filename.endswith("rclpy/service.py") and f.name == "send_response")
        or (f.filename.endswith("rclpy/action/server.py") and f.name in _ACTION_ANSWERS)
        for f in frames
    )


_ACTION_ANSWERS = ("_execute_goal_request", "_execute_cancel_request",
                   "_execute_get_result_request", "_send_result_response")


@contextlib.contextmanager
def spun_node(
    rclpy: Any, context: Any, name: str,
    destroying: Callable[[], contextlib.AbstractContextManager[Any]] = contextlib.nullcontext,
) -> Iterator[tuple[Any, list[str]]]:
    """An rclpy node ``name`` in ``context``, spun by its own 4-thread executor on a thread of
    its own, and the list of what the executor's rounds raised; on the way out the spinning
    stops, the executor settles and the node is destroyed (inside ``destroying()``)."""
    from rclpy.executors import MultiThreadedExecutor

    node = rclpy.create_node(name, context=context)
    executor = MultiThreadedExecutor(num_threads=4, context=context)
    executor.add_node(node)
    stop = threading.Event()
    errors: list[str] = []
    thread = threading.Thread(target=spin_executor, args=(executor, stop, errors), daemon=True,
                              name=f"spin-{name}")
    thread.start()
    try:
        yield node, errors
    finally:
        stop.set()
        thread.join(10)
        settle_executor(executor)
        with destroying():
            node.destroy_node()


def settle_executor(executor: Any) -> None:
    """Shut ``executor`` down after its spin loop ended, marking seen the handles that a
    test destroyed under a running callback (rclpy prints each unseen one at exit).

    A multi-threaded executor's callbacks may still be running in its thread pool
    (rclpy's ``shutdown`` leaves the pool alone): they are waited for first, so
    that none fails later on a node destroyed under it, unseen.
    """
    from rclpy._rclpy_pybind11 import InvalidHandle

    pool = getattr(executor, "_executor", None)
    if pool is not None:
        pool.shutdown(wait=True)
    for future in list(getattr(executor, "_futures", [])):
        if isinstance(getattr(future, "_exception", None), InvalidHandle):
            future.exception()  # seen; any other exception is still printed
    executor.shutdown()


def spin_executor(executor: Any, stop: threading.Event, errors: list[str]) -> None:
    """Spin ``executor`` until ``stop`` is set or rclpy shuts down, whatever a round raises.

    A test's rclpy node must keep answering after one callback failed: an
    exception out of a round goes into ``errors`` (its traceback; rclpy's known
    action races and handles destroyed under a running callback are left out)
    and the fixture that owns the node fails the test with it.
    """
    from rclpy._rclpy_pybind11 import InvalidHandle
    from rclpy.executors import ExternalShutdownException

    while not stop.is_set():
        try:
            executor.spin_once(timeout_sec=0.1)
        except ExternalShutdownException:
            return
        except InvalidHandle:
            continue  # an entity a test destroyed while its callback was still answering
        except Exception as exc:
            if not rclpy_action_race(exc):
                errors.append(traceback.format_exc())


CHROMIUM = shutil.which("chromium")
CHROMEDRIVER = shutil.which("chromedriver")


@contextlib.contextmanager
def headless_chromium(prefix: str) -> Iterator[Any]:
    """A selenium driver of Debian's headless chromium with a profile of its own (removed
    after); the caller skips when :data:`CHROMIUM` or :data:`CHROMEDRIVER` is missing."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    assert CHROMIUM is not None and CHROMEDRIVER is not None
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    profile = tempfile.mkdtemp(prefix=f"{prefix}-chromium-")
    for arg in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                "--disable-component-update", "--disable-sync", "--no-first-run",
                "--disable-dev-shm-usage", f"--user-data-dir={profile}"):
        options.add_argument(arg)
    driver = webdriver.Chrome(options=options, service=Service(executable_path=CHROMEDRIVER))
    try:
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


def peak_rss(pid: int) -> int:
    """A process's peak resident set size so far (Linux's VmHWM), in bytes."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) * 1024
    raise AssertionError(f"no VmHWM in /proc/{pid}/status")
