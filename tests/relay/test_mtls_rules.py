"""Access rules that cannot be left off (issue 53, finding 4).

``--zenoh-mtls`` without ``--zenoh-robot``/``--zenoh-relay`` used to start a router with no
access rules at all: with robot2's certificate the red team put on robot1's topics, answered
for robot1's graph, announced robot1 and robot3, and spoke as relay1. Zenoh matches a
certificate to its rules by exact common name only, so the rules cannot be made from the
certificates alone: the relay now refuses to start, naming the options to add. Under the
configuration it asks for, each of those forgeries, made with robot2's certificate on raw
Zenoh against the relay's real process, is dropped by the router.

Every "not delivered" is proved by a control sent after it on the same link (one link keeps
its order): when the control arrives, the forgery would have arrived before it.
"""

from __future__ import annotations

import json
import queue
import re
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import zenoh

from bridge_server.zenoh import keys
from bridge_server.zenoh.link import UNNAMED_MTLS, ZenohOptions
from tests.helpers import ROOT, free_port, ros_env
from tests.relay.procs import Proc
from tests.relay.support import wait_matched

pytestmark = pytest.mark.timeout(120)

READY = re.compile(r"relay listening on ws://127\.0\.0\.1:(\d+)")
WAIT = 20.0
"""Seconds a control is waited for."""


@dataclass
class Fleet:
    """Certificates made by ``roslibpy-lite-relay certs``: relay1 (the router), relay2 and
    robots robot1 and robot2."""

    dir: Path

    def tls(self, name: str) -> list[str]:
        """``name``'s Zenoh TLS options."""
        return ["--zenoh-tls-ca", str(self.dir / "ca.pem"),
                "--zenoh-tls-cert", str(self.dir / f"{name}.pem"),
                "--zenoh-tls-key", str(self.dir / f"{name}.key")]

    def session(self, endpoint: str, name: str) -> Any:
        """A raw Zenoh session of ``name``'s certificate, a client of ``endpoint``."""
        return zenoh.open(ZenohOptions(
            connect=[endpoint], tls_ca=str(self.dir / "ca.pem"),
            tls_cert=str(self.dir / f"{name}.pem"),
            tls_key=str(self.dir / f"{name}.key")).config())


@pytest.fixture
def fleet(tmp_path: Path) -> Fleet:
    """The fleet's certificates (the command the relay guide gives)."""
    done = subprocess.run(
        [sys.executable, "-m", "bridge_server.zenoh.relay", "certs", "--dir",
         str(tmp_path / "fleet"), "--relay", "relay1", "--relay", "relay2", "--relay-host",
         "127.0.0.1", "--robot", "robot1", "--robot", "robot2"],
        cwd=ROOT, env=ros_env(), capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    return Fleet(tmp_path / "fleet")


def _relay(fleet: Fleet, endpoint: str, *names: str) -> list[str]:
    """relay1's command line as the router asking for certificates, with ``names``."""
    return [sys.executable, "-m", "bridge_server.zenoh.relay", "--port", "0",
            "--zenoh-listen", endpoint, *fleet.tls("relay1"), "--zenoh-mtls", *names]


def test_mtls_naming_nobody_is_refused_at_start(fleet: Fleet) -> None:
    """``--zenoh-mtls`` alone: the relay does not start, and says which options to add."""
    relay = Proc(_relay(fleet, f"tls/127.0.0.1:{free_port()}"), ros_env())
    try:
        relay.wait_for(re.compile(r"relay listening|cannot start|refusing to start"))
        said = "\n".join(relay.lines)
        assert relay.proc.wait(10) != 0, said
    finally:
        relay.stop()
    assert "relay listening" not in said
    assert UNNAMED_MTLS in said and "--zenoh-robot NAME" in said and "--zenoh-relay NAME" in said


@pytest.fixture
def router(fleet: Fleet) -> Iterator[str]:
    """relay1 (a real process) as the router with the names the refusal asks for."""
    endpoint = f"tls/127.0.0.1:{free_port()}"
    relay = Proc(_relay(fleet, endpoint, "--zenoh-robot", "robot1", "--zenoh-robot", "robot2",
                        "--zenoh-relay", "relay2"), ros_env())
    try:
        relay.wait_for(READY)
        yield endpoint
    finally:
        relay.stop()


class Heard:
    """What a session's subscribers heard: (key, payload or token event), in order."""

    def __init__(self) -> None:
        self.items: queue.Queue[tuple[str, str]] = queue.Queue()
        self.seen: list[tuple[str, str]] = []

    def __call__(self, sample: Any) -> None:
        what = (sample.payload.to_string() if sample.kind == zenoh.SampleKind.PUT
                else "gone")
        self.items.put((str(sample.key_expr), what))

    def until(self, *wanted: str) -> list[tuple[str, str]]:
        """Everything heard until each key of ``wanted`` was (waited for)."""
        while not set(wanted) <= {k for k, _ in self.seen}:
            self.seen.append(self.items.get(timeout=WAIT))
        return self.seen


def _put_until_heard(session: Any, key: str, heard: Heard) -> None:
    """Put on ``key`` once a subscriber matches it, and wait until ``heard`` has it."""
    pub = session.declare_publisher(key)
    wait_matched(pub)
    pub.put(b"control")
    pub.undeclare()
    heard.until(key)


def _replies(session: Any, key: str) -> list[str]:
    """Every reply to one query of ``key`` (all of them, until the query ends)."""
    return [r.ok.payload.to_string() if r.ok is not None else "error"
            for r in session.get(key, consolidation=zenoh.ConsolidationMode.NONE, timeout=5.0)]


def test_each_forgery_with_robot2s_certificate_is_refused(fleet: Fleet, router: str) -> None:
    """With robot2's certificate: a put on robot1/steady, an answer for robot1/@graph, a
    token announcing robot1 or robot3, relay1's demand token, call and cancel: none reaches
    anyone, while robot1's and relay2's own doings do."""
    robot1 = fleet.session(router, "robot1")
    robot2 = fleet.session(router, "robot2")
    watcher = fleet.session(router, "relay2")  # a relay: it hears every robot's keys
    asked: queue.Queue[str] = queue.Queue()

    def answer(query: Any) -> None:
        asked.put(str(query.key_expr))
        if str(query.key_expr).endswith(keys.GRAPH):
            query.reply(query.key_expr, b"robot1's graph")
        query.drop()

    entities: list[Any] = []
    try:
        heard = Heard()
        entities += [watcher.declare_subscriber(k, heard) for k in ("robot1/**", "robot2/**")]
        tokens = Heard()
        entities += [watcher.liveliness().declare_subscriber(k, tokens)
                     for k in (f"*/{keys.ALIVE}/**", f"*/{keys.DEMAND}/**")]
        entities += [robot1.declare_queryable(f"robot1/{c}", answer)
                     for c in (keys.GRAPH, f"{keys.CALL}/**", f"{keys.CANCEL}/**")]

        # robot1 on its own keys: heard (the watcher's subscription works)
        _put_until_heard(robot1, "robot1/steady", heard)
        # robot2 puts on robot1's topic, then on its own
        robot2.put("robot1/steady", b"forged")
        _put_until_heard(robot2, "robot2/steady", heard)
        assert ("robot1/steady", "forged") not in heard.seen

        # robot2 answers for robot1's graph, then for its own: once its own is answered,
        # the router has had its forged queryable too
        entities.append(robot2.declare_queryable(
            f"robot1/{keys.GRAPH}", lambda q: (q.reply(q.key_expr, b"forged"), q.drop())))
        entities.append(robot2.declare_queryable(
            f"robot2/{keys.GRAPH}", lambda q: (q.reply(q.key_expr, b"robot2's"), q.drop())))
        while _replies(watcher, f"robot2/{keys.GRAPH}") != ["robot2's"]:
            pass
        assert _replies(watcher, f"robot1/{keys.GRAPH}") == ["robot1's graph"]

        # robot2 announces robot1 and robot3, then itself
        zid = str(robot2.zid())
        entities += [robot2.liveliness().declare_token(keys.alive_key(r, zid))
                     for r in ("robot1", "robot3", "robot2")]
        # and declares relay1's demand of robot1's topic, then one of its own
        entities += [robot2.liveliness().declare_token(f"{r}/{keys.DEMAND}/relay1/steady")
                     for r in ("robot1", "robot2")]
        # (each subscriber hears one link's tokens in order: a control for each)
        seen = tokens.until(keys.alive_key("robot2", zid), f"robot2/{keys.DEMAND}/relay1/steady")
        assert {k for k, _ in seen} == {keys.alive_key("robot2", zid),
                                        f"robot2/{keys.DEMAND}/relay1/steady"}, seen

        # relay2's own call and cancel reach robot1; robot2's, as relay1, do not
        for relay, session in (("relay2", watcher), ("relay1", robot2)):
            for chunk, name in ((keys.CALL, "srv"), (keys.CANCEL, "goal1")):
                _replies(session, f"robot1/{chunk}/{relay}/{name}")  # ended: answered or not
        got = []
        while not asked.empty():
            got.append(asked.get())
        assert f"robot1/{keys.GRAPH}" in got
        assert [k for k in got if "relay" in k] == [f"robot1/{keys.CALL}/relay2/srv",
                                                   f"robot1/{keys.CANCEL}/relay2/goal1"], got
    finally:
        for entity in entities:
            entity.undeclare()
        for session in (robot1, robot2, watcher):
            session.close()


def test_the_relays_own_page_lists_no_forged_robot(fleet: Fleet) -> None:
    """The relay's status lists robot2 (which announced itself) and never robot3, which
    robot2's certificate announced first on the same link."""
    import urllib.request

    endpoint = f"tls/127.0.0.1:{free_port()}"
    relay = Proc(_relay(fleet, endpoint, "--zenoh-robot", "robot1", "--zenoh-robot", "robot2"),
                 ros_env())
    robot2 = None
    try:
        port = int(relay.wait_for(READY).group(1))
        robot2 = fleet.session(endpoint, "robot2")
        zid = str(robot2.zid())
        tokens = [robot2.liveliness().declare_token(keys.alive_key(r, zid))
                  for r in ("robot3", "robot2")]
        deadline = time.monotonic() + WAIT
        while True:  # the relay's process tells no event of a robot it sees
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/status.json",
                                        timeout=10) as r:
                names = [robot["name"] for robot in json.load(r)["robots"]]
            if "robot2" in names or time.monotonic() > deadline:
                break
        assert names == ["robot2"], names
        for token in tokens:
            token.undeclare()
    finally:
        if robot2 is not None:
            robot2.close()
        relay.stop()
