"""The MCP server's role filter in process (issue 54): which tools RobotTools offers for a
role, each decision asserted exactly. Over MockRos, the bridge's own session in memory, with
a role given to the session as the bridge's handshake gives a token's; and over a small fake
of what RobotTools asks (listings, type loads, ``/rosapi/may_*``) for answers a bridge gives
rarely: no may_* service, a refused listing, a type it cannot describe, an answer without
names, a refusal after the listing. The fast tests of scripts/mutate-modules.txt's line."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import pytest

from msgs.runtime import lookup
from rosbridge_core.memory.link import MemoryLink
from rosbridge_core.security.auth import Principal
from rosbridge_core.security.permissions import Role
from roslibpy_lite import MockRos
from roslibpy_lite.exceptions import (
    Forbidden,
    RosLibError,
    RosTimeoutError,
    ServiceError,
)
from roslibpy_lite.mcp import tools as tools_module
from roslibpy_lite.mcp.tools import Options, RobotTools
from tests.mcp.support import text

READING = {"list_topics", "list_services", "list_actions", "list_nodes", "describe_type",
           "read_topic", "collect_topic"}
"""The generic tools every role that may introspect is offered."""
PARAMS = {"get_param", "set_param", "list_params"}
GOALS = {"follow_goal", "cancel_goal"}
STRING, SETBOOL, FIBONACCI = "std_msgs/msg/String", "std_srvs/srv/SetBool", \
    "test_msgs/action/Fibonacci"
WAIT = 7.5  # the Options.timeout of the fake's tests: every question must carry it


def _names(listed: Iterable[Any]) -> set[str]:
    return {t.name for t in listed}


# -- over MockRos, the bridge's session with a role ------------------------------------------


def _ros_as(monkeypatch: pytest.MonkeyPatch, grants: dict[str, list[str]]) -> MockRos:
    """A MockRos whose session holds a principal of a role with ``grants`` (introspection on
    everything besides), as the bridge's handshake gives a token's principal to the link."""
    role = Role.from_table("agent", {"introspection": ["*"], **grants})
    monkeypatch.setattr(MemoryLink, "principal", Principal("agent", role, b"", b""))
    return MockRos()


async def _robot(ros: MockRos) -> None:
    """The robot's side: topics /cmd_vel and /status, services /reset and /shutdown, actions
    /nav and /dock (the mock's client serves those: the roles grant serve_*)."""
    ros.inject("/cmd_vel", {"data": "a"}, STRING)
    ros.inject("/status", {"data": "b"}, STRING)
    for name in ("/reset", "/shutdown"):
        await ros.advertise_service(name, SETBOOL, lambda req: {"success": True})
    for name in ("/nav", "/dock"):
        await ros.advertise_action(name, FIBONACCI, lambda goal, handle: {"sequence": []})


SERVE = {"serve_service": ["*"], "serve_action": ["*"]}


async def test_a_role_s_grants_are_the_tools_it_is_offered(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Through the bridge's session: a role that may publish on /cmd*, call /reset, send
    goals to /nav and change *_display parameters gets exactly those typed tools, the
    parameter tools and the goal tools, besides the reading ones."""
    ros = _ros_as(monkeypatch, {**SERVE, "publish": ["/cmd*"], "call_service": ["/reset"],
                                "send_action_goal": ["/nav"], "params": ["*_display"]})
    await _robot(ros)
    listed = _names(await RobotTools(ros).list_tools())
    assert listed == READING | PARAMS | GOALS | {"publish__cmd_vel", "call__reset",
                                                 "send_goal__nav"}


async def test_a_viewer_is_offered_reading_tools_only(monkeypatch: pytest.MonkeyPatch) -> None:
    """Through the bridge's session: a role with introspection alone (its may_* questions
    refused) is offered the reading tools only: no typed tool, no parameter tool, and no
    goal tool while it may send no goal."""
    ros = _ros_as(monkeypatch, SERVE)
    await _robot(ros)
    assert _names(await RobotTools(ros).list_tools()) == READING


# -- over a fake of what RobotTools asks ---------------------------------------------------------


@dataclass
class _Entity:
    name: str
    type: str


@dataclass
class _Goal:
    """A goal still running when its caller stops waiting."""

    id: str
    status: Any = field(default_factory=lambda: SimpleNamespace(name="EXECUTING"))
    last_feedback: Any = None

    async def result(self, wait: float) -> Any:
        """Still running."""
        raise RosTimeoutError("still running")


@dataclass
class _Bridge:
    """What RobotTools asks of its client, answered from tables: the graph (``topic_types``,
    ``service_types``, ``action_types``: name -> type), what a listing raises (``refuse``, by
    kind), the names each capability's may_* allows (``may``; a capability not in it: all)
    or what it raises (``may_raise``), an answer given to every may_* instead (``answer``),
    the types that cannot be loaded (``undescribable``) and what calling a service raises
    (``call_raise``). It records each may_* question (service, type, names, timeout), the
    other waits it was given, and the services called and goals sent."""

    topic_types: dict[str, str] = field(default_factory=dict)
    service_types: dict[str, str] = field(default_factory=dict)
    action_types: dict[str, str] = field(default_factory=dict)
    refuse: dict[str, Exception] = field(default_factory=dict)
    may: dict[str, set[str]] = field(default_factory=dict)
    may_raise: dict[str, Exception] = field(default_factory=dict)
    answer: dict[str, Any] | None = None
    undescribable: dict[str, Exception] = field(default_factory=dict)
    call_raise: dict[str, Exception] = field(default_factory=dict)
    asked: list[tuple[str, str, list[str], float]] = field(default_factory=list)
    waits: list[float] = field(default_factory=list)
    called: list[str] = field(default_factory=list)

    @property
    def graph(self) -> _Bridge:
        """The graph's listings are asked of the fake itself."""
        return self

    def on_status(self, callback: Any) -> None:
        """Presence's subscription (no status ever comes)."""

    async def _listing(self, kind: str, table: dict[str, str], timeout: float) -> list[_Entity]:
        self.waits.append(timeout)
        if kind in self.refuse:
            raise self.refuse[kind]
        return [_Entity(n, t) for n, t in table.items()]

    async def topics(self, timeout: float) -> list[_Entity]:
        """The topics, as the bridge lists them."""
        return await self._listing("topics", self.topic_types, timeout)

    async def services(self, timeout: float) -> list[_Entity]:
        """The services, as the bridge lists them."""
        return await self._listing("services", self.service_types, timeout)

    async def actions(self, timeout: float) -> list[_Entity]:
        """The actions, as the bridge lists them."""
        return await self._listing("actions", self.action_types, timeout)

    async def load_types(self, type_name: str, timeout: float) -> tuple[Any]:
        """The type's class (msgs' own), or what it is set to raise."""
        self.waits.append(timeout)
        if type_name in self.undescribable:
            raise self.undescribable[type_name]
        return (lookup(type_name),)

    async def call_service(self, name: str, type_name: Any, args: Any, timeout: float) -> Any:
        """A may_* question answered from the tables; another service's call answered
        ``success`` (or refused as set)."""
        if not name.startswith("/rosapi/may_"):
            self.called.append(name)
            if name in self.call_raise:
                raise self.call_raise[name]
            return type_name.Response(success=True, message=f"{name} done")
        capability = name.removeprefix("/rosapi/may_")
        self.asked.append((name, type_name, list(args["names"]), timeout))
        if capability in self.may_raise:
            raise self.may_raise[capability]
        if self.answer is not None:
            return self.answer
        allowed = self.may.get(capability)
        return {"names": [n for n in args["names"] if allowed is None or n in allowed]}

    async def send_goal(self, name: str, cls: Any, goal: Any) -> _Goal:
        """A goal that keeps running."""
        self.called.append(name)
        return _Goal(f"goal-{len(self.called)}")


def _asked(capability: str, names: list[str]) -> tuple[str, str, list[str], float]:
    """A may_* question as the fake records it."""
    return (f"/rosapi/may_{capability}", "rosapi_msgs/srv/MayUse", names, WAIT)


def _tools(bridge: _Bridge, **options: Any) -> RobotTools:
    return RobotTools(bridge, Options(timeout=WAIT, **options))  # type: ignore[arg-type]


NO_PARAMS: dict[str, Exception] = {"params": Forbidden("forbidden: role agent may not params")}


async def test_each_kind_is_asked_in_batches_with_its_names_type_and_timeout(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Two names a question: may_publish is asked [/t0, /t1], [/t2, /t3], [/t4] and
    may_call_service [/s0, /s1], each as rosapi_msgs/srv/MayUse with the server's timeout,
    may_send_action_goal not at all (no action); exactly the allowed names get tools, and
    every listing and type load waits the server's timeout; a tool names its type."""
    monkeypatch.setattr(tools_module, "_ASK_AT_ONCE", 2)
    bridge = _Bridge(topic_types={f"/t{i}": STRING for i in range(5)},
                     service_types={"/s0": SETBOOL, "/s1": SETBOOL},
                     may={"publish": {"/t1", "/t3", "/t4"}, "call_service": {"/s1"}})
    listed = {t.name: t for t in await _tools(bridge).list_tools()}
    assert set(listed) == READING | PARAMS | {"publish__t1", "publish__t3", "publish__t4",
                                              "call__s1"}
    assert f'of type "{STRING}" on the topic "/t1"' in (listed["publish__t1"].description or "")
    assert bridge.asked == [_asked("params", []), _asked("publish", ["/t0", "/t1"]),
                            _asked("publish", ["/t2", "/t3"]), _asked("publish", ["/t4"]),
                            _asked("call_service", ["/s0", "/s1"])]
    assert bridge.waits == [WAIT] * (3 + 4)  # three listings, four types loaded


async def test_the_parameter_question_is_asked_once_with_no_names(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Whether the role may use parameters is one may_params question naming nothing, even
    at one name a question; allowed, the three parameter tools are offered."""
    monkeypatch.setattr(tools_module, "_ASK_AT_ONCE", 1)
    bridge = _Bridge()
    assert _names(await _tools(bridge).list_tools()) == READING | PARAMS
    assert bridge.asked == [_asked("params", [])]


@pytest.mark.parametrize(("refusal", "offered"), [
    pytest.param(Forbidden("forbidden: role agent may not params"), set(), id="forbidden"),
    pytest.param(ServiceError("/rosapi/may_params", "unknown service"), PARAMS,
                 id="no-may-service")])
async def test_the_parameter_tools_follow_the_may_params_answer(
        refusal: Exception, offered: set[str]) -> None:
    """may_params refused as Forbidden: no parameter tool; a bridge without the service
    (ServiceError): the tools are offered and its refusals say the rest."""
    bridge = _Bridge(may_raise={"params": refusal})
    assert _names(await _tools(bridge).list_tools()) == READING | offered


async def test_a_forbidden_question_offers_none_a_missing_service_offers_all() -> None:
    """may_publish Forbidden: no publish tool; may_call_service a ServiceError (a bridge
    without it): every service is offered; the answer for goals is kept as given."""
    bridge = _Bridge(topic_types={"/t": STRING}, service_types={"/a": SETBOOL, "/b": SETBOOL},
                     action_types={"/x": FIBONACCI, "/y": FIBONACCI},
                     may={"send_action_goal": {"/y"}},
                     may_raise={**NO_PARAMS, "publish": Forbidden("forbidden: publish"),
                                "call_service": ServiceError("/rosapi/may_call_service",
                                                             "unknown service")})
    listed = _names(await _tools(bridge).list_tools())
    assert listed == READING | GOALS | {"call__a", "call__b", "send_goal__y"}


@pytest.mark.parametrize("refusal", [
    pytest.param(Forbidden("forbidden: role agent may not introspect"), id="forbidden"),
    pytest.param(ServiceError("/rosapi/topics", "no such service"), id="service-error")])
async def test_a_refused_listing_leaves_the_other_kinds(refusal: Exception) -> None:
    """A listing the role may not make (Forbidden) or the bridge cannot (ServiceError) gives
    no tools of its kind; the other kinds' tools are still offered."""
    bridge = _Bridge(topic_types={"/t": STRING}, service_types={"/s": SETBOOL},
                     action_types={"/x": FIBONACCI}, refuse={"topics": refusal},
                     may_raise=NO_PARAMS)
    assert _names(await _tools(bridge).list_tools()) == READING | GOALS | {"call__s",
                                                                           "send_goal__x"}
    bridge.refuse = {"services": refusal, "actions": refusal}
    assert _names(await _tools(bridge).list_tools()) == READING | {"publish__t"}


async def test_internal_untyped_refused_and_undescribable_names_get_no_tool() -> None:
    """The bridge's own services, hidden names, nodes' parameter services and names without
    a type are never asked about; a name the role may not use and a type the robot cannot
    describe (either error) give no tool, and the names after them still do."""
    bridge = _Bridge(
        topic_types={"/weird": "pkg/msg/Gone", "/denied": STRING, "/_hidden/t": STRING,
                     "/parameter_events": STRING, "/untyped": "", "/ok": STRING},
        service_types={"/odd": "pkg/srv/Gone2", "/rosapi/topics": SETBOOL,
                       "/node/set_parameters": SETBOOL, "/ok_srv": SETBOOL},
        may={"publish": {"/weird", "/ok"}, "call_service": {"/odd", "/ok_srv"}},
        may_raise=NO_PARAMS,
        undescribable={"pkg/msg/Gone": ValueError("no such type"),
                       "pkg/srv/Gone2": RosLibError("cannot describe")})
    assert _names(await _tools(bridge).list_tools()) == READING | {"publish__ok", "call__ok_srv"}
    assert bridge.asked[1:] == [_asked("publish", ["/weird", "/denied", "/ok"]),
                                _asked("call_service", ["/odd", "/ok_srv"])]


async def test_an_answer_without_names_allows_nothing() -> None:
    """A may_* answer without a names field, or naming things that are not names, allows
    nothing and is no error."""
    bridge = _Bridge(topic_types={"/t": STRING}, service_types={"/s": SETBOOL},
                     answer={"other": ["/t", "/s"]})
    assert _names(await _tools(bridge).list_tools()) == READING | PARAMS
    bridge.answer = {"names": [None, 5, ["/t"], {"/s": 1}]}
    assert _names(await _tools(bridge).list_tools()) == READING | PARAMS


async def test_read_only_offers_the_reading_tools_and_asks_nothing_else() -> None:
    """Read-only: exactly the generic tools marked read-only (get_param and list_params when
    parameters are allowed, follow_goal, not set_param or cancel_goal), no typed tool
    whatever the role, and only may_params is asked."""
    bridge = _Bridge(topic_types={"/t": STRING}, service_types={"/s": SETBOOL},
                     action_types={"/x": FIBONACCI})
    listed = _names(await _tools(bridge, read_only=True).list_tools())
    assert listed == READING | {"get_param", "list_params", "follow_goal"}
    assert bridge.asked == [_asked("params", [])]
    bridge.may_raise = NO_PARAMS
    listed = _names(await _tools(bridge, read_only=True).list_tools())
    assert listed == READING | {"follow_goal"}


async def test_goal_tools_are_offered_while_a_goal_may_be_sent_or_runs() -> None:
    """follow_goal and cancel_goal: not offered with no action the role may use, offered with
    one, and still offered after the action left while a goal this server sent runs."""
    bridge = _Bridge(action_types={"/x": FIBONACCI}, may={"send_action_goal": set()},
                     may_raise=NO_PARAMS)
    robot = _tools(bridge)
    assert _names(await robot.list_tools()) == READING
    bridge.may = {}
    assert _names(await robot.list_tools()) == READING | GOALS | {"send_goal__x"}
    result = await robot.call("send_goal__x", {"goal": {"order": 3}, "timeout": 1})
    assert not result.is_error and '"goal_id": "goal-1"' in text(result), text(result)
    bridge.action_types = {}
    assert _names(await robot.list_tools()) == READING | GOALS


async def test_a_refused_call_withdraws_its_tool_and_tells_the_client() -> None:
    """A typed tool's call that the bridge refuses (Forbidden) is a tool error, the client is
    told the list changed (once), and the next listing lacks that tool though may_* still
    allows it; another tool's call answers the service's response."""
    bridge = _Bridge(service_types={"/a": SETBOOL, "/b": SETBOOL}, may_raise=NO_PARAMS,
                     call_raise={"/a": Forbidden("call_service: forbidden: role agent may "
                                                 "not call_service on /a")})
    changes: list[int] = []

    async def on_change() -> None:
        changes.append(len(bridge.called))

    robot = RobotTools(bridge, Options(timeout=WAIT), on_change)  # type: ignore[arg-type]
    assert _names(await robot.list_tools()) == READING | {"call__a", "call__b"}
    result = await robot.call("call__b", {"request": {"data": True}})
    assert not result.is_error
    assert text(result) == '{"success": true, "message": "/b done"}'
    result = await robot.call("call__a", {"request": {"data": True}})
    assert result.is_error and "may not call_service on /a" in text(result)
    assert changes == [2]
    assert _names(await robot.list_tools()) == READING | {"call__b"}


async def test_a_listing_over_its_bound_offers_find_tools() -> None:
    """A listing bound too small for any tool lists only find_tools, saying how many tools it
    left out (none in summary), and find_tools gives a left-out tool's definition."""
    bridge = _Bridge(topic_types={"/t": STRING}, may_raise=NO_PARAMS)
    robot = _tools(bridge, max_list=1001)
    listed = await robot.list_tools()
    assert _names(listed) == {"find_tools"}
    (finder,) = listed
    left_out = len(READING) + 1
    assert f"0 tools are listed in summary and {left_out} are not listed" in \
        (finder.description or "")
    result = await robot.call("find_tools", {"query": "publish__"})
    assert not result.is_error and '"name": "publish__t"' in text(result), text(result)
