"""The fault-injecting proxy itself (bench/linkproxy.py), over a plain TCP echo server."""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from collections.abc import Iterator

import pytest

from bench.linkproxy import LinkProxy


@pytest.fixture
def echo() -> Iterator[tuple[str, int]]:
    """A threaded TCP echo server on 127.0.0.1."""
    with echo_server() as address:
        yield address


@contextlib.contextmanager
def echo_server() -> Iterator[tuple[str, int]]:
    """A threaded TCP echo server on 127.0.0.1 while the block runs."""
    srv = socket.create_server(("127.0.0.1", 0))
    stop = threading.Event()

    def serve(conn: socket.socket) -> None:
        with conn, contextlib.suppress(OSError):  # the proxy resets connections on purpose
            while data := conn.recv(65536):
                conn.sendall(data)

    def accept() -> None:
        srv.settimeout(0.1)
        while not stop.is_set():
            try:
                conn, _ = srv.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            threading.Thread(target=serve, args=(conn,), daemon=True).start()

    t = threading.Thread(target=accept, daemon=True)
    t.start()
    yield srv.getsockname()
    stop.set()
    t.join()
    srv.close()


def _recv_exactly(sock: socket.socket, n: int) -> bytes:
    out = b""
    while len(out) < n:
        chunk = sock.recv(n - len(out))
        if not chunk:
            raise ConnectionError("closed")
        out += chunk
    return out


def test_carries_bytes_both_ways(echo: tuple[str, int]) -> None:
    """Bytes sent through the proxy come back unchanged."""
    with LinkProxy(echo) as link, socket.create_connection(("127.0.0.1", link.port), 5) as s:
        payload = bytes(range(256)) * 400
        s.sendall(payload)
        assert _recv_exactly(s, len(payload)) == payload
        assert link.connections == 1


def test_blackhole_holds_bytes_until_restore(echo: tuple[str, int]) -> None:
    """A blackhole carries nothing and closes nothing; after restore the held bytes arrive in order."""
    with LinkProxy(echo) as link, socket.create_connection(("127.0.0.1", link.port), 5) as s:
        s.sendall(b"before")
        assert _recv_exactly(s, 6) == b"before"
        link.blackhole()
        s.sendall(b"during")
        s.settimeout(0.5)
        with pytest.raises(TimeoutError):
            s.recv(10)
        link.restore()
        s.settimeout(5)
        assert _recv_exactly(s, 6) == b"during"


def test_cut_resets_the_connection(echo: tuple[str, int]) -> None:
    """cut() resets open connections: the client's next read fails with a reset, not EOF."""
    with LinkProxy(echo) as link, socket.create_connection(("127.0.0.1", link.port), 5) as s:
        s.sendall(b"x")
        assert _recv_exactly(s, 1) == b"x"
        link.cut()
        with pytest.raises(ConnectionResetError):
            for _ in range(100):
                s.sendall(b"y")
                if not s.recv(1):
                    break
                time.sleep(0.01)


def test_latency_delays_each_way(echo: tuple[str, int]) -> None:
    """With 100 ms each way an echo takes at least 200 ms (a lower bound, not a speed claim)."""
    with LinkProxy(echo) as link, socket.create_connection(("127.0.0.1", link.port), 5) as s:
        link.set_latency(0.1)
        t0 = time.monotonic()
        s.sendall(b"ping")
        assert _recv_exactly(s, 4) == b"ping"
        assert time.monotonic() - t0 >= 0.2


def test_bandwidth_cap_paces_a_transfer(echo: tuple[str, int]) -> None:
    """At 200 kB/s each way, 200 kB cannot come back in much under a second."""
    with LinkProxy(echo) as link, socket.create_connection(("127.0.0.1", link.port), 5) as s:
        link.set_bandwidth(200_000)
        payload = b"z" * 200_000
        t0 = time.monotonic()
        threading.Thread(target=s.sendall, args=(payload,), daemon=True).start()
        assert _recv_exactly(s, len(payload)) == payload
        assert time.monotonic() - t0 >= 0.8


def test_refuse_resets_new_connections(echo: tuple[str, int]) -> None:
    """While refusing, a new connection is reset at once; after restore it is carried again."""
    with LinkProxy(echo) as link:
        link.refuse()
        # reset at connect, send or receive, or EOF
        with pytest.raises(ConnectionError), socket.create_connection(("127.0.0.1", link.port), 5) as s:
            s.sendall(b"a")
            if not s.recv(1):
                raise ConnectionError("closed")
        link.restore()
        with socket.create_connection(("127.0.0.1", link.port), 5) as s:
            s.sendall(b"b")
            assert _recv_exactly(s, 1) == b"b"


def _echo_once(port: int) -> None:
    with socket.create_connection(("127.0.0.1", port), 5) as s:
        s.sendall(b"hi")
        assert _recv_exactly(s, 2) == b"hi"


def test_several_targets_share_connections_round_robin() -> None:
    """Given three targets the proxy is a round-robin balancer: six connections go two to
    each; with a target down, new connections go to the one that is up and none is refused."""
    with contextlib.ExitStack() as stack:
        targets = [stack.enter_context(echo_server()) for _ in range(3)]
        with LinkProxy(targets) as link:
            for _ in range(6):
                _echo_once(link.port)
            assert list(link.carried.values()) == [2, 2, 2]
    with socket.socket() as closed:
        closed.bind(("127.0.0.1", 0))  # bound, never listening: connections are refused
        down = closed.getsockname()
        with echo_server() as up, LinkProxy([down, up]) as link:
            for _ in range(4):
                _echo_once(link.port)
            assert link.carried == {down: 0, up: 4}
