"""The blocking client in the places scripts run: many threads, a notebook's loop, Ctrl+C, exit."""

from __future__ import annotations

import asyncio
import signal
import subprocess
import sys
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import psutil
import pytest

from roslibpy_lite import ConnectError, ConnectionClosed, ConnectionState, sync
from tests.helpers import ROOT, BridgeProcess, ros_env, threads_since, wait_until
from tests.sync.support import heard

MULT = "mult_msgs/srv/MultFloats"


def _sockets() -> set[tuple[Any, Any]]:
    """This process's TCP/UDP connections, by their two addresses."""
    return {(c.laddr, c.raddr) for c in psutil.Process().net_connections(kind="inet")}


def test_many_threads_share_one_client(bridge: BridgeProcess, topic: str) -> None:
    """Eight threads call, publish and read through one client at once; every answer is right."""
    with sync.connect(bridge.url) as ros:
        ros.advertise_service(topic, MULT, lambda req: {"result": req["x"] * req["y"]})
        pub = ros.advertise(topic + "_t", "std_msgs/msg/Int32")

        def work(i: int) -> list[float]:
            answers = []
            for j in range(20):
                pub.publish({"data": i})
                reply = ros.call_service(topic, MULT, {"x": float(i), "y": float(j)}, timeout=30)
                answers.append(reply["result"])
            return answers

        with ThreadPoolExecutor(8) as pool:
            results = list(pool.map(work, range(8)))
        assert results == [[float(i * j) for j in range(20)] for i in range(8)]
        pub.flush()
        assert pub.handle.published == 160


def test_works_inside_a_running_event_loop(bridge: BridgeProcess, topic: str) -> None:
    """Called by plain code on a thread whose asyncio loop is running (a notebook cell), it works."""

    def cell() -> Any:  # what a user types in a Jupyter cell: no await
        with sync.connect(bridge.url) as ros, \
                ros.advertise_service(topic, MULT, lambda req: {"result": req["x"] + req["y"]}):
            return ros.call_service(topic, MULT, {"x": 1.0, "y": 2.0}, timeout=15)

    async def notebook() -> Any:
        asyncio.get_running_loop()  # the kernel's loop is running on this thread
        return cell()

    assert asyncio.run(notebook()) == {"result": 3.0}


def test_close_leaves_no_thread_or_socket(bridge: BridgeProcess, topic: str) -> None:
    """After close, the threads and sockets the client used (loop, handlers, resolver) are gone.

    Threads and sockets are compared as sets, not counted: what earlier tests of this worker
    left to end on its own (an executor's threads, a bridge's pipes) may end meanwhile."""
    threads, sockets = set(threading.enumerate()), _sockets()

    def new_threads() -> list[str]:
        return threads_since(threads)

    with sync.connect(bridge.url) as ros:
        ros.advertise_service(topic, MULT, lambda req: {"result": 1.0})
        assert ros.call_service(topic, MULT, {}, timeout=15) == {"result": 1.0}
        sub = ros.subscribe(topic + "_t", "std_msgs/msg/Int32")
        assert new_threads() and _sockets() - sockets
    assert sub.closed
    assert not new_threads(), new_threads()
    wait_until(lambda: not _sockets() - sockets, 5, "the client's socket to close")
    with sync.MockRos() as mock:
        mock.advertise_service("/s", MULT, lambda req: {"result": 1.0})
        mock.call_service("/s", MULT, {})
        assert new_threads()  # MockRos runs its loop on a thread of its own
    assert not new_threads(), new_threads()


def test_connect_failure_leaves_no_thread() -> None:
    """A refused connection raises ConnectError and stops the loop thread it started."""
    threads = threading.active_count()
    with pytest.raises(ConnectError, match=r"127\.0\.0\.1:9"):
        sync.connect("ws://127.0.0.1:9", reconnect=False, open_timeout=2)
    assert threading.active_count() == threads


def test_reconnects_and_restores(make_bridge: Callable[..., BridgeProcess], topic: str) -> None:
    """After the bridge restarts, the blocking client reconnects and its subscription resumes."""
    first = make_bridge()
    with sync.connect(first.url) as ros:
        changes = ros.state_changes()
        pub = ros.advertise(topic, "std_msgs/msg/Int32")
        sub = ros.subscribe(topic, "std_msgs/msg/Int32")
        pub.publish({"data": 1})
        wait_until(lambda: sub.handle.pending, 15, "the first message")
        first.kill()
        assert changes.next(10) is ConnectionState.RECONNECTING
        make_bridge(port=first.port)
        assert changes.next(30) is ConnectionState.CONNECTED
        assert heard(pub, sub, {"data": 2}, lambda msg: msg == {"data": 2}) == {"data": 2}


CTRL_C = """
import sys, threading
from roslibpy_lite import sync, RosTimeoutError

with sync.connect(sys.argv[1]) as ros:
    sub = ros.subscribe("/nobody_publishes_here", "std_msgs/msg/Int32")
    try:
        print("waiting", flush=True)
        sub.get()                      # blocks until Ctrl+C
    except KeyboardInterrupt:
        print("interrupted", flush=True)
    try:                               # the pending get was cancelled: a new one may wait
        sub.get(0.2)
    except RosTimeoutError:
        print("still usable", flush=True)
print("threads", threading.active_count(), flush=True)
"""


def test_ctrl_c_interrupts_a_blocking_call(bridge: BridgeProcess) -> None:
    """SIGINT during a blocking get raises KeyboardInterrupt there; the client stays usable and closes."""
    proc = subprocess.Popen([sys.executable, "-c", CTRL_C, bridge.url], cwd=ROOT, env=ros_env(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == "waiting"
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    assert out.split("\n")[:3] == ["interrupted", "still usable", "threads 1"], out + err


def test_handler_may_close_the_client() -> None:
    """A handler that closes its own client (on a worker thread) ends the pending call cleanly."""
    threads = threading.active_count()
    ros = sync.MockRos()
    ros.advertise_service("/shutdown", "std_srvs/srv/Empty", lambda req: ros.close())
    with pytest.raises(ConnectionClosed, match="closed"):
        ros.call_service("/shutdown", "std_srvs/srv/Empty", {}, timeout=5)
    assert ros.state is ConnectionState.CLOSED
    wait_until(lambda: threading.active_count() == threads, 5, "the worker thread to end")


def test_client_options_are_forwarded(make_bridge: Callable[..., BridgeProcess], tmp_path: Any) -> None:
    """sync.connect takes the asyncio client's options: a token opens a bridge that requires one."""
    from roslibpy_lite import NotAuthenticated
    from tests.security.support import make_auth_file

    auth = make_auth_file(tmp_path)
    bridge = make_bridge("--auth-file", str(auth.path))
    with sync.connect(bridge.url, token=auth.tokens["admin"], reconnect=False) as ros:
        assert ros.is_connected
    with pytest.raises(NotAuthenticated):
        sync.connect(bridge.url, token="wrong", open_timeout=5)



def _publish_until_closed(pub: sync.Publisher[Any], started: threading.Barrier,
                          ended: list[str]) -> None:
    started.wait()
    try:
        while True:
            pub.publish({"data": 1})
    except ConnectionClosed:
        ended.append("closed")
    except BaseException as exc:  # the test reports what else ended it
        ended.append(repr(exc))


def test_close_while_threads_publish() -> None:
    """The loop stopping while other threads publish: each gets ConnectionClosed, none hangs."""
    for _ in range(20):
        ros = sync.MockRos()
        pub = ros.advertise("/race", "std_msgs/msg/Int32")
        started = threading.Barrier(5)
        ended: list[str] = []
        threads = [threading.Thread(target=_publish_until_closed, args=(pub, started, ended))
                   for _ in range(4)]
        for t in threads:
            t.start()
        started.wait()
        ros._loop.stop()  # under the publishers (close() would end the handles first)
        for t in threads:
            t.join(10)
        assert not any(t.is_alive() for t in threads)
        assert ended == ["closed"] * 4
