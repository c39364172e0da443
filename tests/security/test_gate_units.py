"""The gate (rosbridge_core/security/gate.py) on its own, with a session, link and verifier
played here: the op rate and its burst, the frame size before authentication, the auth op,
the handshake timer, each refusal's text, take-over and rosapi filtering. In the test
process, so that mutation testing (scripts/mutate.sh) sees every check (issue 54)."""

from __future__ import annotations

import asyncio
import logging
from dataclasses import dataclass, field
from typing import Any

import pytest

from rosbridge_core.protocol.ops import parse_op
from rosbridge_core.security import gate as gate_module
from rosbridge_core.security.auth import Principal
from rosbridge_core.security.gate import POLICY_VIOLATION, PRE_AUTH_FRAME_LIMIT, Gate
from rosbridge_core.security.options import SecurityConfig
from rosbridge_core.security.permissions import Role, filter_rosapi
from rosbridge_core.session.session import ROSAPI_REQUESTS

pytestmark = pytest.mark.timeout(30)

VIEWER = Role.from_table("viewer", {"subscribe": ["/seen*"], "call_service": ["/srv"],
                                    "introspection": ["/seen*"], "take_over": ["/mine"]})
ALICE = Principal("alice", VIEWER, b"s", b"d")
BOB = Principal("bob", VIEWER, b"s", b"d")


class Clock:
    """time.monotonic as the gate sees it, moved by the test."""

    def __init__(self) -> None:
        self.now = 100.0

    def monotonic(self) -> float:
        return self.now


@dataclass
class Holder:
    """What a link's holder of fragment memory is told."""

    became: list[str] = field(default_factory=list)

    def become(self, name: str) -> None:
        self.became.append(name)


@dataclass
class Link:
    """A client link: records closes and frame limits."""

    remote_address: tuple[str, int] = ("10.0.0.7", 5000)
    closes: list[tuple[int, str]] = field(default_factory=list)
    limits: list[int | None] = field(default_factory=list)
    closed: asyncio.Event = field(default_factory=asyncio.Event)
    holder: Holder | None = None

    async def close(self, code: int, reason: str) -> None:
        self.closes.append((code, reason))
        self.closed.set()

    def limit_frames(self, size: int | None) -> None:
        self.limits.append(size)


@dataclass
class Session:
    """The guarded session: what the gate tells it."""

    loop: asyncio.AbstractEventLoop
    link: Link = field(default_factory=Link)
    sid: int = 7
    closed: bool = False
    statuses: list[tuple[str, str]] = field(default_factory=list)
    refused: list[tuple[Any, str]] = field(default_factory=list)

    def status(self, level: str, msg: str, id: Any = None) -> None:
        self.statuses.append((level, msg))

    def refuse(self, op: Any, why: str) -> None:
        self.refused.append((op, why))

    def recheck_grants(self) -> int:
        return 0


@dataclass
class Verifier:
    """The bridge's security as the gate asks it: ``auth`` set when there is an auth file;
    ``answer`` what the auth op's token proves."""

    config: SecurityConfig = field(default_factory=SecurityConfig)
    auth: Any = None
    answer: Principal | str = "invalid token"
    asked: list[tuple[str, str, str]] = field(default_factory=list)

    def verify_auth_op(self, address: str, mac: str, who: str) -> Principal | str:
        self.asked.append((address, mac, who))
        return self.answer


@pytest.fixture
def clock(monkeypatch: pytest.MonkeyPatch) -> Clock:
    """The gate's clock, held still until the test moves it."""
    fake = Clock()
    monkeypatch.setattr(gate_module, "time", fake)
    return fake


def _gate(principal: Principal | None = ALICE, *, auth: bool = False, rate: float = 0.0,
          burst: int = 0, handshake: float = 10.0) -> tuple[Gate, Session, Verifier]:
    config = SecurityConfig(max_op_rate=rate, op_burst=burst, handshake_timeout=handshake)
    verifier = Verifier(config, auth=object() if auth else None)
    session = Session(asyncio.get_running_loop())
    return Gate(verifier, session, principal, ROSAPI_REQUESTS), session, verifier  # type: ignore[arg-type]


async def _closed(session: Session) -> tuple[int, str]:
    await asyncio.wait_for(session.link.closed.wait(), 5)
    (close,) = session.link.closes
    return close


async def test_the_op_rate_admits_the_burst_warns_once_then_closes(clock: Clock) -> None:
    """At 10 ops/s with a burst of 3: three frames at once pass, the next three are dropped
    with one warning naming the rate and burst, the seventh (past twice the burst) closes."""
    gate, session, _ = _gate(rate=10, burst=3)
    assert [gate.admit_frame() for _ in range(6)] == [True] * 3 + [False] * 3
    assert session.statuses == [("warning", "op rate limit: at most 10 ops per second "
                                 "(burst 3); ops over it are dropped, and the connection "
                                 "closes if this goes on")]
    assert not gate.closing
    assert gate.admit_frame() is False
    assert await _closed(session) == (POLICY_VIOLATION, "too many ops: more than 10 per second")
    assert gate.admit_frame() is False  # nothing after a close


async def test_the_op_rate_refills_with_time_up_to_the_burst(clock: Clock) -> None:
    """Tokens come back at the rate and never past the burst; once over half the burst
    again, the next overflow warns again."""
    gate, session, _ = _gate(rate=10, burst=4)
    assert [gate.admit_frame() for _ in range(5)] == [True] * 4 + [False]
    clock.now += 0.2  # two tokens back: -1 + 2
    assert [gate.admit_frame() for _ in range(2)] == [True, False]
    assert len(session.statuses) == 1
    clock.now += 60  # a minute: the burst, not 600 tokens
    assert [gate.admit_frame() for _ in range(5)] == [True] * 4 + [False]
    assert len(session.statuses) == 2  # warned again: it had recovered past half the burst


async def test_warning_again_needs_more_than_half_the_burst(clock: Clock) -> None:
    """Recovering to exactly half the burst keeps the warning given: no second one."""
    gate, session, _ = _gate(rate=1, burst=4)
    assert [gate.admit_frame() for _ in range(5)] == [True] * 4 + [False]
    clock.now += 3  # -1 + 3 = 2 tokens; 1 left after the next frame: not over half
    assert [gate.admit_frame() for _ in range(3)] == [True, True, False]
    assert len(session.statuses) == 1


async def test_the_burst_defaults_to_one_second_of_the_rate(clock: Clock) -> None:
    """Without --op-burst the burst is the rate's whole ops (2 at 2.5/s), at least 1."""
    gate, _, _ = _gate(rate=2.5)
    assert gate.burst == 2
    assert [gate.admit_frame() for _ in range(3)] == [True, True, False]
    slow, _, _ = _gate(rate=0.5)
    assert slow.burst == 1 and slow.admit_frame() and not slow.admit_frame()


async def test_without_a_rate_every_frame_passes(clock: Clock) -> None:
    """--max-op-rate 0: no limit, however many frames at once."""
    gate, session, _ = _gate()
    assert all(gate.admit_frame() for _ in range(1000))
    assert session.statuses == []


async def test_before_authentication_only_small_frames_are_read() -> None:
    """An unauthenticated client may send a frame of PRE_AUTH_FRAME_LIMIT bytes, not one
    more: that closes the connection naming the size. Authenticated, any size passes."""
    gate, session, _ = _gate(None, auth=True)
    assert gate.admit_frame(PRE_AUTH_FRAME_LIMIT)
    assert not gate.admit_frame(PRE_AUTH_FRAME_LIMIT + 1)
    assert await _closed(session) == (
        POLICY_VIOLATION, f"authentication required before a frame of {PRE_AUTH_FRAME_LIMIT + 1} "
                          "bytes")
    gate.end()
    authed, _, _ = _gate(ALICE, auth=True)
    assert authed.admit_frame(10 * PRE_AUTH_FRAME_LIMIT)


async def test_without_a_token_the_handshake_timer_closes() -> None:
    """No auth op within the handshake timeout: the connection is closed saying so."""
    gate, session, _ = _gate(None, auth=True, handshake=0.05)
    assert not gate.authenticated
    code, reason = await _closed(session)
    assert code == POLICY_VIOLATION and reason.startswith("authentication required: send a "
                                                          "token (Authorization: Bearer")


async def test_the_handshake_timer_stops_at_the_auth_op_and_at_the_end() -> None:
    """An auth op that proves a principal, or the session's end, stops the timer."""
    gate, session, verifier = _gate(None, auth=True, handshake=0.05)
    verifier.answer = ALICE
    assert gate.check(parse_op({"op": "auth", "mac": "token"})) is False
    ended, quiet, _ = _gate(None, auth=True, handshake=0.05)
    ended.end()
    ended.end()  # twice: harmless
    await asyncio.sleep(0.2)  # four handshake timeouts
    assert session.link.closes == [] and quiet.link.closes == []


async def test_a_session_without_an_auth_file_needs_no_token() -> None:
    """No auth file: authenticated at once, no timer, an auth op changes nothing."""
    gate, _, verifier = _gate(None, handshake=0.01)
    assert gate.authenticated and gate._timer is None
    assert gate.check(parse_op({"op": "auth", "mac": "token"})) is False
    assert verifier.asked == [] and gate.principal is None
    assert gate.check(parse_op({"op": "subscribe", "topic": "/anything"}))


async def test_the_auth_op_authenticates_and_lifts_the_frame_limit() -> None:
    """A good auth op: the principal and its role hold from now on, the link reads full
    frames again, the link's holder counts for the principal, the verifier was asked with
    the client's address."""
    gate, session, verifier = _gate(None, auth=True)
    session.link.holder = Holder()
    verifier.answer = ALICE
    assert not gate.check(parse_op({"op": "subscribe", "topic": "/seen"}))
    assert await _closed(session) == (
        POLICY_VIOLATION, "authentication required before 'subscribe': send the auth op first")
    gate, session, verifier = _gate(None, auth=True)
    session.link.holder = Holder()
    verifier.answer = ALICE
    assert gate.check(parse_op({"op": "auth", "mac": "token"})) is False
    assert (gate.principal, gate.role, gate.authenticated) == (ALICE, VIEWER, True)
    assert verifier.asked == [("10.0.0.7", "token", "session 7")]
    assert session.link.limits == [None] and session.link.holder.became == ["alice"]
    assert gate._timer is None
    assert gate.check(parse_op({"op": "subscribe", "topic": "/seen"}))
    gate.check(parse_op({"op": "auth", "mac": "token"}))  # the same principal again: fine
    assert session.link.closes == [] and session.link.limits == [None]


async def test_a_bad_token_or_another_principal_closes() -> None:
    """An auth op whose token proves nothing closes with the verifier's reason; one for
    another principal than the connection's closes naming the one it has."""
    gate, session, verifier = _gate(None, auth=True)
    verifier.answer = "invalid token"
    gate.check(parse_op({"op": "auth", "mac": "bad"}))
    assert await _closed(session) == (POLICY_VIOLATION, "invalid token")
    assert gate.principal is None and not gate.authenticated
    gate, session, verifier = _gate(ALICE, auth=True)
    verifier.answer = BOB
    gate.check(parse_op({"op": "auth", "mac": "bobs"}))
    assert await _closed(session) == (
        POLICY_VIOLATION, "this connection is authenticated as alice already; open a new "
                          "connection to use another token")
    assert gate.principal is ALICE


async def test_close_happens_once_and_not_on_a_closed_session() -> None:
    """A second close, or a close of a session already gone, sends nothing more; the
    reason is cut to 120 characters (a websocket close reason's room)."""
    gate, session, _ = _gate()
    gate.close("x" * 200)
    gate.close("again")
    assert await _closed(session) == (POLICY_VIOLATION, "x" * 120)
    gone, dead, _ = _gate()
    dead.closed = True
    gone.close("late")
    await asyncio.sleep(0)
    assert dead.link.closes == [] and not gone.closing


async def test_each_refusal_names_the_role_the_capability_and_the_name() -> None:
    """What the role lacks is refused naming role, capability and name; an action's or a
    node's internals name what they are part of; bad names are refused as such; an op that
    needs nothing passes."""
    gate, session, _ = _gate()
    checks = {
        "publish": {"op": "publish", "topic": "/seen", "msg": {}},
        "subscribe_ok": {"op": "subscribe", "topic": "/seen/x"},
        "subscribe": {"op": "subscribe", "topic": "/hidden"},
        "relative": {"op": "subscribe", "topic": "seen"},
        "action": {"op": "call_service", "service": "/fib/_action/send_goal"},
        "params": {"op": "call_service", "service": "/node/get_parameters"},
        "rosapi": {"op": "call_service", "service": "/rosapi/get_param", "args": ["/n:p", ""]},
        "call_ok": {"op": "call_service", "service": "/srv"},
        "bad_name": {"op": "subscribe", "topic": "/a b"},
        "nul": {"op": "call_service", "service": "/rosapi/get_param",
                "args": {"name": "/n:p\x00"}},
        "unsubscribe": {"op": "unsubscribe", "topic": "/hidden"},
    }
    passed = {key: gate.check(parse_op(op)) for key, op in checks.items()}
    assert [k for k, ok in passed.items() if ok] == ["subscribe_ok", "relative", "call_ok",
                                                      "unsubscribe"]
    why = [w for _, w in session.refused]
    assert why[:5] == [
        "forbidden: role viewer may not publish on /seen",
        "forbidden: role viewer may not subscribe on /hidden",
        "forbidden: role viewer may not send_action_goal on /fib "
        "(/fib/_action/send_goal is part of it)",
        "forbidden: role viewer may not params on /node:* (/node/get_parameters is part of it)",
        "forbidden: role viewer may not params on /n:p",
    ]
    assert why[5].startswith("invalid topic name '/a b'") and "contains a control" in why[6]
    assert len(why) == 7


async def test_without_a_role_every_name_is_allowed_but_names_are_still_checked() -> None:
    """No roles (no auth file): anything allowed, nothing filtered; bad names still refused."""
    gate, session, _ = _gate(None)
    assert gate.check(parse_op({"op": "publish", "topic": "/estop", "msg": {}}))
    assert gate.forbids("publish", "/estop") is None and gate.sees("/anything")
    values = {"topics": ["/a"], "types": ["t"]}
    assert gate.filter_rosapi("/rosapi/topics", values) is values
    assert not gate.check(parse_op({"op": "subscribe", "topic": "/a b"}))
    assert len(session.refused) == 1


async def test_forbids_answers_for_some_name_or_one() -> None:
    """forbids: ``*`` asks whether the role has the capability on any name at all."""
    gate, _, _ = _gate()
    assert gate.forbids("subscribe", "*") is None
    assert gate.forbids("publish", "*") == "role viewer may not publish on any name"
    assert gate.forbids("subscribe", "/hidden") == "role viewer may not subscribe on /hidden"
    assert gate.forbids("subscribe", "/fib/_action/status") == (
        "role viewer may not send_action_goal on /fib")
    assert gate.sees("/seen/a") and not gate.sees("/hidden")


async def test_a_rosapi_refusal_does_not_name_rosapi_as_a_part() -> None:
    """allowed() adds "(X is part of it)" only for a name other than the governing one that
    is not a rosapi service."""
    gate, session, _ = _gate()
    op = parse_op({"op": "call_service", "service": "/rosapi/nodes"})
    assert not gate.allowed(op, "params", "/n:p", used="/rosapi/get_param")
    assert not gate.allowed(op, "params", "/n:p", used="/n:p")
    assert not gate.allowed(op, "params", "/n:p", used="/n/get_parameters")
    assert [w for _, w in session.refused] == [
        "forbidden: role viewer may not params on /n:p",
        "forbidden: role viewer may not params on /n:p",
        "forbidden: role viewer may not params on /n:p (/n/get_parameters is part of it)"]


async def test_take_over_by_a_freed_name_the_same_principal_or_the_role() -> None:
    """A name its owner failed to defend may be taken once; the owner's own principal may
    take it; otherwise only a role with take_over on it."""
    owner, _, _ = _gate(BOB)
    me, _, _ = _gate(ALICE)
    owner.freed.add("/x")
    assert me.may_take_over("/x", owner) and "/x" not in owner.freed
    assert not me.may_take_over("/x", owner)
    assert me.may_take_over("/mine", owner) and me.may_take_over("/mine", None)
    assert not me.may_take_over("/x", None)
    again, _, _ = _gate(BOB)
    assert again.may_take_over("/x", owner)
    anonymous, _, _ = _gate(None)
    other, _, _ = _gate(None)
    assert not anonymous.may_take_over("/x", other)


async def test_rosapi_answers_and_args_are_filtered_by_the_role() -> None:
    """A rosapi list keeps what the role sees; rosapi args given as a list are read by the
    service's field names (the parameter's name decides)."""
    gate, _, _ = _gate()
    assert gate.filter_rosapi("/rosapi/topics", {"topics": ["/seen", "/hidden"],
                                                 "types": ["a", "b"]}) == {
        "topics": ["/seen"], "types": ["a"]}
    assert gate_module._rosapi_args(ROSAPI_REQUESTS["/rosapi/get_param"], ["/n:p", "d"]) == {
        "name": "/n:p", "default_value": "d"}
    assert gate_module._rosapi_args(ROSAPI_REQUESTS["/rosapi/get_param"], {"name": "/n:q"}) == {"name": "/n:q"}
    assert gate_module._rosapi_args(ROSAPI_REQUESTS["/rosapi/get_param"], None) == {}
    params = Role.from_table("p", {"params": ["/n:p"]})
    p_gate, p_session, _ = _gate(Principal("p", params, b"s", b"d"))
    assert p_gate.check(parse_op({"op": "call_service", "service": "/rosapi/get_param",
                                  "args": ["/n:p", ""]}))
    assert not p_gate.check(parse_op({"op": "call_service", "service": "/rosapi/get_param",
                                      "args": ["/n:q", ""]}))
    assert [w for _, w in p_session.refused] == ["forbidden: role p may not params on /n:q"]


# -- the role's own checks (permissions.py) ---------------------------------------------------


def test_a_deny_of_every_name_takes_the_capability_away() -> None:
    """has(): a deny pattern made only of ``*`` takes the capability (asked for some name)
    away; a narrower deny, or a deny of another capability, does not."""
    def role(deny: dict[str, list[str]]) -> Role:
        return Role.from_table("r", {"publish": ["*"], "subscribe": ["*"], "deny": deny})

    assert not role({"publish": ["*"]}).has("publish")
    assert not role({"publish": ["**"]}).has("publish")
    assert role({"publish": ["/a*"]}).has("publish")
    assert role({"publish": ["X*"]}).has("publish")
    assert role({"subscribe": ["*"]}).has("publish")
    assert not Role.from_table("r", {"subscribe": ["*"]}).has("publish")


def test_a_rosapi_list_keeps_a_parallel_column_it_cannot_line_up() -> None:
    """A column of another length than the names (or no list) is left as it is; one of the
    same length is filtered row by row."""
    shown = filter_rosapi(VIEWER, "/rosapi/topics",
                                      {"topics": ["/hidden", "/seen"], "types": ["a"]})
    assert shown == {"topics": ["/seen"], "types": ["a"]}
    shown = filter_rosapi(VIEWER, "/rosapi/topics",
                                      {"topics": ["/hidden", "/seen"], "types": None})
    assert shown == {"topics": ["/seen"], "types": None}


@pytest.mark.parametrize(("node", "shown"), [("/hidden", ""), ("/seen/node", "/seen/node"),
                                             ("", "")])
def test_a_lookup_naming_a_node_the_role_may_not_see_is_blanked(node: str, shown: str) -> None:
    """rosapi's service_node answer keeps a node the role sees, and blanks one it may not
    see to "" (as for an unknown service)."""
    assert filter_rosapi(VIEWER, "/rosapi/service_node", {"node": node}) == {
        "node": shown}


def test_a_roles_table_is_read_and_each_mistake_named() -> None:
    """Capabilities given twice add up (``all`` and one of its own); ``limits`` is read;
    each malformed entry is refused naming the role and the key."""
    role = Role.from_table("r", {"all": ["/a"], "publish": ["/b"],
                                 "limits": {"fragment_bytes": 1000}})
    assert role.allow["publish"] == ("/a", "/b") and role.allow["subscribe"] == ("/a",)
    assert role.limits == {"fragment_bytes": 1000}
    from rosbridge_core.security.permissions import CAPABILITIES, RoleError

    mistakes: list[tuple[dict[str, Any], str]] = [
        ({"limits": {"fragment_bytes": -1}}, "role r: limits.fragment_bytes must be a whole "
                                             "number of bytes >= 0 (0: no limit), got -1"),
        ({"deny": ["/x"]}, "role r: 'deny' must be a table of capabilities"),
        ({"deny": {"publish": "/x"}}, "role r: deny.publish must be a list of name patterns"),
        ({"publish": ["/x", 1]}, "role r: publish must be a list of name patterns"),
        ({"fly": ["/x"]}, f"role r: unknown capability 'fly' (known: all, "
                          f"{', '.join(CAPABILITIES)})"),
    ]
    for table, message in mistakes:
        with pytest.raises(RoleError) as info:
            Role.from_table("r", table)
        assert str(info.value) == message


@pytest.mark.parametrize(("capability", "name", "needs"), [
    ("call_service", "/a/_action/send_goal", ("send_action_goal", "/a")),
    ("call_service", "/a/_action/status", ("call_service", "/a/_action/status")),
    ("subscribe", "/a/_action/feedback", ("send_action_goal", "/a")),
    ("subscribe", "/a/_action/get_result", ("subscribe", "/a/_action/get_result")),
    ("publish", "/a/_action/status", ("serve_action", "/a")),
    ("publish", "/a/_action/send_goal", ("publish", "/a/_action/send_goal")),
    ("call_service", "/a/_action/b/_action/send_goal", ("send_action_goal", "/a/_action/b")),
    ("call_service", "/_action/send_goal", ("call_service", "/_action/send_goal")),
    ("call_service", "/node/get_parameters", ("params", "/node:*")),
    ("call_service", "get_parameters", ("call_service", "get_parameters")),
    ("subscribe", "/parameter_events", ("params", "*:*")),
    ("publish", "/parameter_events", ("params", "*:*")),
    ("call_service", "/parameter_events", ("call_service", "/parameter_events")),
])
def test_what_a_name_of_another_capabilitys_internals_needs(
        capability: str, name: str, needs: tuple[str, str]) -> None:
    """An action's services and topics, a node's parameter services and /parameter_events
    need what governs them; anything else what it names."""
    from rosbridge_core.security.permissions import hidden_requirement

    assert hidden_requirement(capability, name) == needs


@pytest.mark.parametrize(("service", "args", "needs"), [
    ("/rosapi/get_param", {}, ("params", "*")),
    ("/rosapi/get_param", {"name": "n:p"}, ("params", "/n:p")),
    ("/rosapi/get_param_names", {}, ("params", "*")),
    ("/rosapi/topics", {}, ("introspection", "*")),
    ("/rosapi/topic_type", {"topic": "chatter"}, ("introspection", "/chatter")),
    ("/rosapi/node_details", {"node": "/talker"}, ("introspection", "/talker")),
])
def test_what_a_rosapi_call_needs(service: str, args: dict[str, Any],
                                  needs: tuple[str, str]) -> None:
    """Parameter services need params on the parameter (any, without a name); lookups of one
    name introspection on it; lists introspection on some name."""
    from rosbridge_core.security.permissions import rosapi_requirement

    assert rosapi_requirement(service, args) == needs


def test_a_control_character_in_a_rosapi_name_is_refused_saying_so() -> None:
    """A NUL in a rosapi name is refused quoting it: ROS names never hold one."""
    from rosbridge_core.security.permissions import UnsafeNameError, rosapi_requirement

    with pytest.raises(UnsafeNameError) as info:
        rosapi_requirement("/rosapi/topic_type", {"topic": "/a\x00"})
    assert str(info.value) == ("/rosapi/topic_type: topic '/a\\x00' contains a control "
                               "character (such as NUL); ROS names never do")


async def test_what_the_gate_logs_and_whom_it_refuses(clock: Clock,
                                                      caplog: pytest.LogCaptureFixture) -> None:
    """The gate logs who authenticated (at the handshake or by an auth op), a session over
    the op rate, each close with its reason and an auth op for another principal; each
    refusal is handed the op refused."""
    caplog.set_level(logging.INFO, "bridge_server")
    gate, session, _ = _gate(rate=1, burst=1)
    assert gate.admit_frame() and not gate.admit_frame()
    gate.close("enough")
    op = parse_op({"op": "subscribe", "topic": "/hidden"})
    gate.check(op)
    bad = parse_op({"op": "call_service", "service": "/a b"})
    gate.check(bad)
    assert [o for o, _ in session.refused] == [op, bad]
    assert session.refused[1][1].startswith("invalid service name '/a b'")
    late, _, verifier = _gate(None, auth=True)
    verifier.answer = ALICE
    late.check(parse_op({"op": "auth", "mac": "t"}))
    verifier.answer = BOB
    late.check(parse_op({"op": "auth", "mac": "t"}))
    assert caplog.messages == ["client 7 authenticated as alice (role viewer)",
                               "session 7: over the op rate",
                               "session 7: closing: enough",
                               "client 7 authenticated as alice (role viewer) by an auth op",
                               "session 7: auth op for another principal refused",
                               "session 7: closing: this connection is authenticated as alice "
                               "already; open a new connection to use another token"]
    await _closed(session)


async def test_warned_again_only_past_half_the_burst(clock: Clock) -> None:
    """With a burst of 1 the first overflow warns; with a burst of 4, recovering to exactly
    half of it keeps the warning given."""
    one, session, _ = _gate(rate=1, burst=1)
    assert one.admit_frame() and not one.admit_frame()
    assert len(session.statuses) == 1
    four, session, _ = _gate(rate=1, burst=4)
    assert [four.admit_frame() for _ in range(5)] == [True] * 4 + [False]
    clock.now += 4  # -1 + 4 = 3 tokens: 2 left after the next frame, exactly half
    assert [four.admit_frame() for _ in range(4)] == [True] * 3 + [False]
    assert len(session.statuses) == 1


async def test_the_handshake_close_says_how_to_give_a_token() -> None:
    """The handshake timer's reason names every way to give a token."""
    _, session, _ = _gate(None, auth=True, handshake=0.01)
    assert (await _closed(session))[1] == (
        "authentication required: send a token (Authorization: Bearer, ?token= or an auth "
        "op) within the handshake timeout")


def test_rosapi_args_given_as_a_list_are_read_by_the_services_fields() -> None:
    """Extra list items past the service's fields are ignored; a service without known
    fields reads none."""
    assert gate_module._rosapi_args(ROSAPI_REQUESTS["/rosapi/get_param"], ["/n:p", "d", "extra"]) == {
        "name": "/n:p", "default_value": "d"}
    assert gate_module._rosapi_args((), ["a"]) == {}
