"""A relay's admission (bridge_server/zenoh/relay.py) on its own: each way a websocket
request is turned away before any robot's Bridge sees it, with its status, text and
counted reason, and the ``auth`` op of a connection that gave no token. No Zenoh network:
the relay is made, not started, and what it asks (its security, its robots) is played
here, so mutation testing (scripts/mutate.sh) sees every check (issue 54)."""

from __future__ import annotations

import asyncio
import json
import logging
from dataclasses import dataclass, field
from typing import Any

import pytest
from websockets.datastructures import Headers, MultipleValuesError
from websockets.exceptions import ConnectionClosedOK
from websockets.frames import Close
from websockets.http11 import Request, Response
from websockets.server import ServerProtocol

from bridge_server.foxglove import SUBPROTOCOL as FOXGLOVE
from bridge_server.front.server import BridgeConfig
from bridge_server.http.web import Reply
from bridge_server.zenoh.link import ZenohOptions
from bridge_server.zenoh.relay import Relay
from rosbridge_core.security.auth import Principal
from rosbridge_core.security.gate import POLICY_VIOLATION
from rosbridge_core.security.options import SecurityConfig
from rosbridge_core.security.permissions import Role

pytestmark = pytest.mark.timeout(30)

LAB = Role.from_table("lab", {"subscribe": ["*"], "robots": ["robot1"]})
ALICE = Principal("alice", LAB, b"s", b"d")
UPGRADE = {"Connection": "keep-alive, Upgrade", "Upgrade": "websocket"}


@dataclass
class Conn:
    """A websocket server connection as the relay's admission uses it."""

    remote_address: tuple[str, int] = ("10.0.0.7", 5000)
    subprotocol: str | None = None
    frames: list[Any] = field(default_factory=list)
    closes: list[tuple[int, str]] = field(default_factory=list)
    principal: Principal | None = field(default_factory=lambda: None)  # del-able
    gone: bool = False
    """Whether the client left: closing then raises ConnectionClosed."""
    robot_name: str = ""

    def respond(self, status: int, text: str) -> Response:
        return ServerProtocol().reject(status, text)

    async def recv(self) -> Any:
        if not self.frames:
            await asyncio.sleep(3600)  # a client that sends nothing
        frame = self.frames.pop(0)
        if isinstance(frame, BaseException):
            raise frame
        return frame

    async def close(self, code: int, reason: str) -> None:
        if self.gone:
            raise ConnectionClosedOK(Close(1000, ""), None)
        self.closes.append((code, reason))


@dataclass
class Robots:
    """The robots a relay opens, played: ``known`` names have a Bridge."""

    known: set[str] = field(default_factory=lambda: {"robot1", "robot2"})
    asked: list[str] = field(default_factory=list)
    admitted: list[tuple[Any, Any, bool]] = field(default_factory=list)

    async def robot(self, name: str) -> Any:
        self.asked.append(name)
        if name not in self.known:
            return None
        robots = self

        class Bridge:
            robot_name = name

            async def admit(self, connection: Any, request: Any, secured: bool) -> str:
                robots.admitted.append((connection, request, secured))
                return f"admitted by {name}"

        return Bridge()


@pytest.fixture
def relay(monkeypatch: pytest.MonkeyPatch) -> tuple[Relay, Robots]:
    """A relay that reached its router (a session stands for it) with robot1 and robot2."""
    made = Relay(BridgeConfig(port=0, node_name="relay",
                              security=SecurityConfig(handshake_timeout=0.05)),
                 ZenohOptions(connect=["tcp/127.0.0.1:7447"]), relay_id="relay-a")
    robots = Robots()
    monkeypatch.setattr(made, "robot", robots.robot)
    made.session = object()  # type: ignore[assignment]
    return made, robots


def _request(path: str, upgrade: bool = True) -> Request:
    return Request(path, Headers(UPGRADE if upgrade else {}))


async def _admit(made: Relay, conn: Conn, path: str, upgrade: bool = True) -> Any:
    """What the relay answers ``conn``'s request for ``path`` (a websocket upgrade, or not)."""
    return await made._process_request(conn, _request(path, upgrade))  # type: ignore[arg-type]


def _said(response: Response | None) -> tuple[int, str]:
    assert response is not None
    return response.status_code, response.body.decode()


async def test_a_plain_get_is_a_status_route_or_404(relay: tuple[Relay, Robots],
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """A request that is no websocket upgrade goes to the relay's pages (asked with the
    client's address): a page is answered as it is, no page is 404 "no such page"; no robot
    is opened by the admission itself."""
    made, robots = relay
    asked: list[tuple[str, str]] = []

    async def answer(request: Request, address: str) -> Reply | None:
        asked.append((request.path, address))
        return Reply(200, b"the page\n") if request.path == "/" else None

    monkeypatch.setattr(made.web, "answer", answer)
    assert _said(await _admit(made, Conn(), "/nope", upgrade=False)) == (
        404, "no such page\n")
    assert _said(await _admit(made, Conn(), "/", upgrade=False)) == (
        200, "the page\n")
    assert asked == [("/nope", "10.0.0.7"), ("/", "10.0.0.7")]
    assert robots.asked == [] and made.refused == {}


async def test_before_the_router_answers_clients_are_told_to_come_back(
        relay: tuple[Relay, Robots], caplog: pytest.LogCaptureFixture) -> None:
    """No Zenoh session yet: 503 naming the router dialed, Retry-After 1, counted and
    logged."""
    caplog.set_level(logging.INFO, "bridge_server")
    made, robots = relay
    made.session = None
    response = await _admit(made, Conn(), "/robot1")
    assert _said(response) == (503, "this relay has not reached its Zenoh router yet "
                                    "(tcp/127.0.0.1:7447): try again shortly\n")
    assert response is not None and response.headers["Retry-After"] == "1"
    assert made.refused == {"no_router": 1} and robots.asked == []
    assert "refused a client: this relay has not reached its Zenoh router yet" in caplog.messages


@pytest.mark.parametrize("path", ["/", "", "/?token=x", "//"])
async def test_a_path_naming_no_robot_is_refused(relay: tuple[Relay, Robots], path: str
                                                 ) -> None:
    """A websocket path without a robot's name: 404 saying how to name one, counted."""
    made, robots = relay
    assert _said(await _admit(made, Conn(), path)) == (
        404, "name a robot in the path: ws://<relay>:<port>/<robot>\n")
    assert made.refused == {"no_robot_named": 1} and robots.asked == []


async def test_an_invalid_robot_name_is_refused(relay: tuple[Relay, Robots]) -> None:
    """A name no robot may have: 400 with the reason, counted, nothing opened."""
    made, robots = relay
    status, text = _said(await _admit(made, Conn(), "/bad*name/x"))
    assert status == 400 and "bad*name" in text
    assert made.refused == {"invalid_robot_name": 1} and robots.asked == []


async def test_the_robot_is_the_paths_first_part(relay: tuple[Relay, Robots]) -> None:
    """/robot1/anything?query names robot1, whose Bridge admits the connection secured."""
    made, robots = relay
    conn = Conn()
    del conn.principal  # a websocket connection has no principal until a token gives one
    request = _request("/robot1/extra/part?token=t")
    answer = await made._process_request(conn, request)  # type: ignore[arg-type]
    assert answer == "admitted by robot1"  # type: ignore[comparison-overlap]
    assert robots.asked == ["robot1"] and robots.admitted == [(conn, request, True)]
    assert getattr(conn, "robot_bridge").robot_name == "robot1"  # noqa: B009
    assert made.refused == {}


async def test_a_robot_not_on_zenoh_is_404(relay: tuple[Relay, Robots],
                                           caplog: pytest.LogCaptureFixture) -> None:
    """A valid name no robot on the network has: 404 naming it (whole, slashes only taken
    off its ends), counted and logged."""
    caplog.set_level(logging.INFO, "bridge_server")
    made, _ = relay
    assert _said(await _admit(made, Conn(), "/robot3")) == (
        404, "no robot named 'robot3' is connected to this relay's Zenoh network\n")
    assert _said(await _admit(made, Conn(), "/XrobotX/")) == (
        404, "no robot named 'XrobotX' is connected to this relay's Zenoh network\n")
    assert made.refused == {"unknown_robot": 2}
    assert caplog.messages == ["refused a client asking for robot robot3: not on Zenoh",
                               "refused a client asking for robot XrobotX: not on Zenoh"]


@pytest.mark.parametrize(("status", "reason"), [(401, "auth"), (429, "too_many"),
                                                (418, "http_418")])
async def test_a_security_refusal_is_passed_on_and_counted(
        relay: tuple[Relay, Robots], monkeypatch: pytest.MonkeyPatch, status: int, reason: str
) -> None:
    """What the relay's security refuses (origin, limits, token) is the answer, counted by
    its status; no robot is opened."""
    made, robots = relay
    refusal = ServerProtocol().reject(status, "no\n")

    async def refuse(connection: Any, request: Any) -> Response:
        return refusal

    monkeypatch.setattr(made.security, "process_request", refuse)
    assert await _admit(made, Conn(), "/robot1") is refusal
    assert made.refused == {reason: 1} and robots.asked == []


async def test_a_header_given_twice_is_a_clean_400(relay: tuple[Relay, Robots],
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """A header that must be given once, given twice: 400 naming it."""
    made, robots = relay

    async def twice(connection: Any, request: Any) -> Response:
        raise MultipleValuesError("Authorization")

    monkeypatch.setattr(made.security, "process_request", twice)
    assert _said(await _admit(made, Conn(), "/robot1")) == (
        400, "header 'Authorization' sent more than once\n")
    assert robots.asked == []


async def test_a_role_reaches_only_its_robots(relay: tuple[Relay, Robots],
                                              monkeypatch: pytest.MonkeyPatch,
                                              caplog: pytest.LogCaptureFixture) -> None:
    """A principal whose role does not reach the robot: 403 naming role and robot, the
    robot never opened, each refusal counted and logged naming principal, role and robot;
    the robot it reaches is opened."""
    caplog.set_level(logging.INFO, "bridge_server")
    made, robots = relay

    async def token(connection: Any, request: Any) -> None:
        connection.principal = ALICE

    monkeypatch.setattr(made.security, "process_request", token)
    assert _said(await _admit(made, Conn(), "/robot2")) == (
        403, "role lab may not reach robot 'robot2'\n")
    assert made.refused == {"robot_not_allowed": 1} and robots.asked == []
    await _admit(made, Conn(), "/robot2")
    assert made.refused == {"robot_not_allowed": 2}
    assert caplog.messages.count("refused principal alice (role lab) asking for robot robot2: "
                                 "not among its robots") == 2
    await _admit(made, Conn(), "/robot1")
    assert robots.asked == ["robot1"]


async def test_without_a_token_the_robot_waits_for_the_auth_op(
        relay: tuple[Relay, Robots], monkeypatch: pytest.MonkeyPatch) -> None:
    """With an auth file and no token at the handshake, the connection is let through with
    its robot's name noted, and nothing of the robot is opened yet."""
    made, robots = relay
    monkeypatch.setattr(made.security, "auth", object())

    async def no_token(connection: Any, request: Any) -> None:
        return None

    monkeypatch.setattr(made.security, "process_request", no_token)
    conn = Conn()
    assert await _admit(made, conn, "/robot2") is None
    assert conn.robot_name == "robot2" and robots.asked == []


def _auth_frame(token: str = "tok") -> str:
    return json.dumps({"op": "auth", "mac": token})


async def _first_op(made: Relay, conn: Conn, monkeypatch: pytest.MonkeyPatch,
                    proves: Principal | str = ALICE) -> Any:
    """What the relay makes of a tokenless connection to ``conn.robot_name`` whose
    ``auth`` op proves ``proves``."""
    asked: list[tuple[str, str, str]] = []

    def verify(address: str, mac: str, who: str) -> Principal | str:
        asked.append((address, mac, who))
        return proves

    monkeypatch.setattr(made.security, "verify_auth_op", verify)
    bridge = await made._authenticated_robot(conn, conn.robot_name)  # type: ignore[arg-type]
    if conn.frames == [] and asked:
        assert asked == [("10.0.0.7", "tok", f"a client of {conn.robot_name}")]
    return bridge


async def test_an_auth_op_for_a_reached_robot_opens_it(relay: tuple[Relay, Robots],
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """The first op proves a principal whose role reaches the robot: the robot is opened
    and the connection holds the principal."""
    made, robots = relay
    conn = Conn(frames=[_auth_frame()], robot_name="robot1")
    bridge = await _first_op(made, conn, monkeypatch)
    assert bridge.robot_name == "robot1" and conn.principal is ALICE
    assert conn.closes == [] and robots.asked == ["robot1"]


@pytest.mark.parametrize(("frames", "robot", "proves", "closed", "counted"), [
    ([_auth_frame()], "robot2", ALICE, "role lab may not reach robot 'robot2'",
     "robot_not_allowed"),
    ([_auth_frame()], "robot1", "invalid token", "invalid token", None),
    ([_auth_frame()], "robot9", Principal("any", Role.from_table("any", {}), b"", b""),
     "no robot named 'robot9' is connected to this relay's Zenoh network", "unknown_robot"),
    ([json.dumps({"op": "subscribe", "topic": "/x"})], "robot1", ALICE,
     "authentication required before 'subscribe': send the auth op first", None),
    (["{not json"], "robot1", ALICE,
     "authentication required: the first op must be auth (malformed JSON at line 1 column 2: "
     "Expecting property name e)", None),
    ([_auth_frame()], "robot1", "x" * 200, "x" * 120, None),
    ([], "robot1", ALICE, "authentication required: send a token (Authorization: Bearer, "
     "?token= or an auth op) within the handshake timeout", None),
], ids=["not_reached", "bad_token", "unknown_robot", "other_op", "garbage", "long_reason",
        "silent"])
async def test_a_tokenless_connection_is_closed_saying_why(
        relay: tuple[Relay, Robots], monkeypatch: pytest.MonkeyPatch, frames: list[Any],
        robot: str, proves: Principal | str, closed: str, counted: str | None,
        caplog: pytest.LogCaptureFixture) -> None:
    """Each way the first op fails to admit the connection closes it (1008) saying why,
    cut to 120 characters, within the handshake timeout (0.05 s here; the bound is wide);
    the robot is opened only if the role reaches it."""
    made, robots = relay
    conn = Conn(frames=frames, robot_name=robot)
    loop = asyncio.get_running_loop()
    started = loop.time()
    assert await _first_op(made, conn, monkeypatch, proves) is None
    assert loop.time() - started < 5
    ((code, reason),) = conn.closes
    assert code == POLICY_VIOLATION and reason == closed[:120]
    assert made.refused == ({counted: 1} if counted else {})
    assert robots.asked == (["robot9"] if robot == "robot9" else [])
    if counted == "robot_not_allowed":
        assert ("closed the connection of principal alice (role lab), authenticated by an auth "
                "op, asking for robot robot2: not among its robots") in caplog.messages


async def test_a_foxglove_client_cannot_send_an_auth_op(relay: tuple[Relay, Robots],
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """A Foxglove connection without a token is closed at once: it has no auth op."""
    made, robots = relay
    conn = Conn(subprotocol=FOXGLOVE, frames=[_auth_frame()], robot_name="robot1")
    assert await _first_op(made, conn, monkeypatch) is None
    assert conn.closes == [(POLICY_VIOLATION, "authentication required: give the token in "
                            "the URL (?token=...) or an Authorization header")]
    assert robots.asked == []


async def test_a_refusal_to_a_client_already_gone_is_no_error(
        relay: tuple[Relay, Robots], monkeypatch: pytest.MonkeyPatch) -> None:
    """Closing a connection whose client left meanwhile raises nothing."""
    made, robots = relay
    conn = Conn(frames=[_auth_frame()], robot_name="robot2", gone=True)
    assert await _first_op(made, conn, monkeypatch) is None
    assert made.refused == {"robot_not_allowed": 1} and robots.asked == []


async def test_a_connection_gone_before_its_first_op_is_left_alone(
        relay: tuple[Relay, Robots], monkeypatch: pytest.MonkeyPatch) -> None:
    """The client left before any op: nothing to close, nothing opened."""
    made, robots = relay
    conn = Conn(frames=[ConnectionClosedOK(Close(1000, ""), None)], robot_name="robot1")
    assert await _first_op(made, conn, monkeypatch) is None
    assert conn.closes == [] and robots.asked == []
