"""Fixtures for the whole suite.

- ``bridge``: one bridge process for the session (``.url``, ``.port``, ``.lines``).
- ``make_bridge``: a factory for private bridges (stop, kill, restart on the same port).
- ``ros_node``: an rclpy node in this process, spun by a background executor.
- ``topic``: a name no other test uses (for topics and services).
- ``ws_connect``: raw websocket peers for wire-level tests (closed after the test).
- ``client``: a roslibpy_lite client connected to ``bridge`` (closed after the test).

DDS stays on loopback and every run gets its own ROS_DOMAIN_ID, set here
before anything can initialise rclpy.
"""

from __future__ import annotations

import contextlib
import faulthandler
import itertools
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
from collections.abc import AsyncIterator, Callable, Iterator
from typing import TYPE_CHECKING, Any

import pytest

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
os.environ.setdefault("ROS_DOMAIN_ID", str(os.getpid() % 100 + 1))
# Under pytest-xdist (scripts/test.sh runs two workers), each worker is a DDS world of its own:
# the run's domain for worker gw0, shifted by 101 per worker after it (Fast DDS takes 0-232).
os.environ["ROS_DOMAIN_ID"] = str(
    (int(os.environ["ROS_DOMAIN_ID"])
     + 101 * int(os.environ.get("PYTEST_XDIST_WORKER", "gw0").removeprefix("gw") or 0)) % 233)
# a 5 s participant lease: bridges the tests kill are forgotten in seconds (see the file)
os.environ.setdefault(
    "FASTRTPS_DEFAULT_PROFILES_FILE", os.path.join(os.path.dirname(__file__), "dds_profile.xml")
)

from rosbridge_core.codec import budget
from tests.helpers import BridgeProcess, WireClient, open_wire, spun_node

if TYPE_CHECKING:
    from roslibpy_lite import Client

_names = itertools.count()

# Under CI (CI=true, set by .ci/run), a test that would be skipped because a tool is missing
# (Node.js, Chromium, systemd-analyze, ...) fails instead: a green CI run means all of it ran.
_STRICT_SKIPS = os.environ.get("CI", "").lower() in {"1", "true", "yes"}


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Iterator[None]:
    """Turn a skip into a failure naming its reason when the run is CI's."""
    outcome = yield
    report = outcome.get_result()  # type: ignore[attr-defined]
    if _STRICT_SKIPS and report.skipped and not hasattr(report, "wasxfail"):
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr)
        report.outcome = "failed"
        report.longrepr = f"skipped under CI=true, which needs every test to run: {reason}"


@pytest.hookimpl(hookwrapper=True)
def pytest_make_collect_report(collector: pytest.Collector) -> Iterator[None]:
    """The same for a whole module skipped while collected (a module-level
    ``pytest.importorskip`` or ``pytest.skip(allow_module_level=True)``)."""
    outcome = yield
    report = outcome.get_result()  # type: ignore[attr-defined]
    if _STRICT_SKIPS and report.skipped:
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr)
        report.outcome = "failed"
        report.longrepr = (f"{collector.nodeid} skipped at collection under CI=true, which "
                           f"needs every test to run: {reason}")


_TERMINAL: list[Any] = []
"""The run's own standard error, kept before any test's output is captured."""

# How long a node's teardown may take before the run is ended with every thread's stack.
NODE_DESTROY_LIMIT = 60.0


# Outside this process, so that it can look while a C call here holds the GIL: armed with a
# number of seconds, it prints this process's native stacks (py-spy, if installed) to the
# terminal when they pass before it is told "off". faulthandler shows Python frames only.
_WATCHDOG = """
import os, select, subprocess, sys, time
pid, spy, deadline, buf = sys.argv[1], sys.argv[2], None, b""
while True:
    wait = None if deadline is None else max(0.0, deadline - time.monotonic())
    if select.select([0], [], [], wait)[0]:
        chunk = os.read(0, 4096)
        if not chunk:
            break
        *lines, buf = (buf + chunk).split(b"\\n")
        for line in lines:
            deadline = None if line == b"off" else time.monotonic() + float(line)
    elif deadline is not None:
        deadline = None
        subprocess.run([spy, "dump", "--native", "--pid", pid], stdout=2, check=False)
"""
_WATCHER: list[subprocess.Popen[bytes]] = []


def _watch(line: str) -> None:
    for watcher in _WATCHER:
        with contextlib.suppress(OSError):
            assert watcher.stdin is not None
            watcher.stdin.write(line.encode() + b"\n")
            watcher.stdin.flush()


def pytest_configure(config: pytest.Config) -> None:
    """Keep a handle on the terminal's stderr (pytest captures fd 2 only around each test)
    for :func:`stack_dump_if_stuck`, and give child processes Ctrl+C as a terminal would."""
    _TERMINAL.append(os.fdopen(os.dup(2), "w"))
    spy = shutil.which("py-spy")
    if spy is not None:
        _WATCHER.append(subprocess.Popen([sys.executable, "-c", _WATCHDOG, str(os.getpid()), spy],
                                         stdin=subprocess.PIPE))
    # A run started as a background job of a non-interactive shell (nohup ... &) has SIGINT
    # ignored, and its children would inherit that: the Ctrl+C tests would see no Ctrl+C.
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


@contextlib.contextmanager
def stack_dump_if_stuck(seconds: float) -> Iterator[None]:
    """Run the block; if it has not returned after ``seconds``, print every thread's stack to
    the terminal and end the run with exit status 1.

    For rclpy teardown: a call into rclpy's C side holds the GIL, so pytest-timeout's signal
    never runs and a stuck call would hang the run until CI's limit. faulthandler's watchdog is
    a C thread that needs no GIL; the native stacks come from py-spy in a process outside
    (:data:`_WATCHDOG`), after three quarters of the time."""
    out = _TERMINAL[0] if _TERMINAL else sys.stderr
    _watch(str(seconds * 0.75))  # native stacks first, while this process still runs
    faulthandler.dump_traceback_later(seconds, exit=True, file=out)
    try:
        yield
    finally:
        faulthandler.cancel_dump_traceback_later()
        _watch("off")


def pytest_unconfigure(config: pytest.Config) -> None:
    """After the summary: a thread a test left running (a bridge or robot it did not close
    keeps its ROS spin thread) would make the interpreter wait for it at exit, forever.
    Name them and end the run as failed instead of hanging it."""
    while _TERMINAL:
        _TERMINAL.pop().close()
    while _WATCHER:
        watcher = _WATCHER.pop()
        assert watcher.stdin is not None
        watcher.stdin.close()  # it ends at end of input
        watcher.wait(10)
    budget.close_workers()  # the decoding pool of relays served in this process
    left = [t for t in threading.enumerate()
            if t is not threading.main_thread() and not t.daemon and t.is_alive()]
    for t in left:
        t.join(5.0)
    names = [t.name for t in left if t.is_alive()]
    if names:
        print(f"\nthreads still running after the tests, which a test did not close: "
              f"{', '.join(names)}; exiting instead of waiting for them", file=sys.stderr,
              flush=True)
        os._exit(3)


@pytest.fixture(scope="session")
def bridge() -> Iterator[BridgeProcess]:
    """One running bridge shared by the session."""
    proc = BridgeProcess().start()
    yield proc
    proc.stop()


@pytest.fixture
def make_bridge() -> Iterator[Callable[..., BridgeProcess]]:
    """A factory of private, started bridges; all are stopped after the test."""
    made: list[BridgeProcess] = []

    def factory(*args: str, port: int = 0) -> BridgeProcess:
        proc = BridgeProcess(port=port, args=list(args)).start()
        made.append(proc)
        return proc

    yield factory
    for proc in made:
        # a graceful stop: a killed bridge's participant lingers in the others' view (its
        # lease), where the next test's bridge may take over its ports
        proc.stop()


class _RosRuntime:
    """rclpy initialised once per session, in a context of its own."""

    def __init__(self) -> None:
        import rclpy

        self.rclpy = rclpy
        self.context = rclpy.context.Context()
        rclpy.init(context=self.context)

    def close(self) -> None:
        self.rclpy.shutdown(context=self.context)


@pytest.fixture(scope="session")
def ros_runtime() -> Iterator[_RosRuntime]:
    """The session's rclpy context."""
    runtime = _RosRuntime()
    yield runtime
    runtime.close()


@pytest.fixture
def ros_node(ros_runtime: _RosRuntime, request: pytest.FixtureRequest) -> Iterator[Any]:
    """An rclpy node for this test, spun by its own 4-thread executor, destroyed afterwards.

    Callbacks in a ReentrantCallbackGroup may run concurrently (a slow service
    does not block the node's other callbacks).
    """
    name = "test_" + re.sub(r"\W", "_", request.node.name)[:40] + f"_{next(_names)}"
    with spun_node(ros_runtime.rclpy, ros_runtime.context, name,
                   lambda: stack_dump_if_stuck(NODE_DESTROY_LIMIT)) as (node, errors):
        yield node
    if errors:
        pytest.fail("this test's rclpy executor raised:\n" + errors[0])


@pytest.fixture
def topic(request: pytest.FixtureRequest) -> str:
    """A topic or service name unique to this test."""
    return f"/t{next(_names)}_" + re.sub(r"\W", "_", request.node.name)[:40].strip("_")


@pytest.fixture
async def ws_connect(bridge: BridgeProcess) -> AsyncIterator[Callable[..., Any]]:
    """Open raw websocket peers to the session bridge (or a given URL); all closed afterwards."""
    opened: list[WireClient] = []

    async def connect(url: str | None = None) -> WireClient:
        client = await open_wire(url or bridge.url)
        opened.append(client)
        return client

    yield connect
    for client in opened:
        await client.close()


@pytest.fixture
async def client(bridge: BridgeProcess) -> AsyncIterator[Client]:
    """A client connected to the session's bridge, closed after the test."""
    import roslibpy_lite

    async with roslibpy_lite.connect(bridge.url) as ros:
        yield ros
