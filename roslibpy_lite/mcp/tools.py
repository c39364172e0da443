"""The robot's tools: what an MCP client may list and call, from the live ROS graph.

:class:`RobotTools` holds one roslibpy-lite client (a :class:`~roslibpy_lite.Client` to a
bridge or a relay, or :class:`~roslibpy_lite.MockRos`) and answers ``tools/list`` and
``tools/call``. It knows nothing of MCP's transport; :mod:`roslibpy_lite.mcp.server` wires
it to the SDK. Tools:

- ``list_topics``, ``list_services``, ``list_actions``, ``list_nodes``, ``list_params``,
  ``describe_type``, ``read_topic`` (the next message, bounded wait; an image as an image),
  ``get_param``: reading, offered to every role that may introspect;
- ``publish__<topic>``, ``call__<service>``, ``send_goal__<action>`` (each typed: the input
  schema is the robot's own definition, :mod:`roslibpy_lite.mcp.schema`), ``cancel_goal``
  and ``set_param``: offered only for the names the connection's role may use (asked of the
  bridge, ``/rosapi/may_*``; a bridge that cannot answer is taken at its word when it
  refuses: the tool is withdrawn), and never in read-only mode.

Every call has a timeout; an error (a refusal, a dropped link, a field that does not fit)
is a tool error whose text is the client's own (it names the field or the link's state).
"""

from __future__ import annotations

import asyncio
import contextlib
import contextvars
import json
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass
from typing import Any

import mcp_types as types

from ..data import MAX_PIXELS
from ..exceptions import Forbidden, RosLibError, RosTimeoutError, ServiceError
from ..handles import Publisher
from ..messages import from_wire
from ..ros import RosBase
from .listing import (
    FIND_TOOLS,
    ROBOT_DATA,
    bound_listing,
    find_tools,
    find_tools_tool,
    internal,
    quoted,
    tool_name,
)
from .media import cloud_summary, image
from .presence import GRAPH_TOOLS, Presence
from .schema import message_schema

__all__ = ["MAX_WAIT", "ConfirmationPending", "Options", "RobotTools"]

MAX_WAIT = 120.0
"""The longest any one tool call may wait (seconds), whatever the caller asks."""

_IMAGE_TYPES = {"sensor_msgs/msg/Image": "PNG", "sensor_msgs/msg/CompressedImage": "JPEG"}
_CLOUD = "sensor_msgs/msg/PointCloud2"
_ASK_AT_ONCE = 5000
_SHORT_LIST = 32
_SHORT_BYTES = 64


@dataclass
class Options:
    """How the MCP server serves the robot."""

    read_only: bool = False
    """Offer no tool that changes anything (publish, call, goals, set_param)."""
    timeout: float = 10.0
    """A tool call's default wait (seconds); a call may ask for up to :data:`MAX_WAIT`."""
    image_size: int = 512
    """The longest side of an image handed back (pixels; a call may ask for less or more)."""
    max_text: int = 32_768
    """The most characters of text one tool result carries (longer text is cut, and says so)."""
    max_pixels: int = MAX_PIXELS
    """The most pixels a compressed image read may declare; a larger one is refused before
    it is decoded (a decompression bomb)."""
    max_list: int = 100_000
    """The most characters a ``tools/list`` answer takes: tools past it are listed in summary
    or only counted, and ``find_tools`` gives them (:mod:`roslibpy_lite.mcp.listing`)."""
    confirm: bool = False
    """Ask the MCP client's user to confirm each change (publish, call, goal, cancel,
    set_param) before it is made (MCP elicitation); declined, nothing is sent."""


@dataclass
class _Typed:
    kind: str  # "publish", "call", "send_goal"
    name: str  # the ROS name
    type_name: str
    cls: Any


@dataclass
class _Tool:
    tool: types.Tool
    run: Callable[[dict[str, Any]], Awaitable[list[types.ContentBlock]]]


Progress = Callable[[float, "float | None", "str | None"], Awaitable[None]]
"""Reports a call's progress to the MCP client (``progress, total, message``)."""

_PROGRESS: contextvars.ContextVar[Progress | None] = contextvars.ContextVar(
    "roslibpy_lite_mcp_progress", default=None)

Confirm = Callable[[str], Awaitable[bool]]
"""Asks the MCP client's user to allow a change (the question); True: allowed. It may
raise :class:`ConfirmationPending` to have the question sent as the call's answer."""


class ConfirmationPending(Exception):
    """The confirmation is to be asked in the call's answer (MCP 2026-07-28's
    ``InputRequiredResult``); the client retries the call with the user's answer."""

    def __init__(self, question: str) -> None:
        super().__init__(question)
        self.question = question

PARAM_TOOLS = ("get_param", "set_param", "list_params")
"""The tools offered only to a role with ``params`` on some name."""
GOAL_TOOLS = ("follow_goal", "cancel_goal")
"""The tools offered only while the robot has an action or a goal this server sent runs."""

MAX_COLLECT = 1000
"""The most messages one collect_topic call gathers."""

_CAPABILITY = {"publish": "publish", "call": "call_service", "send_goal": "send_action_goal",
               "params": "params"}
_TYPED = ("publish", "call", "send_goal")


def _obj(properties: dict[str, Any], required: tuple[str, ...] = ()) -> dict[str, Any]:
    return {"type": "object", "properties": properties, "required": list(required),
            "additionalProperties": False}


_TIMEOUT = {"type": "number", "exclusiveMinimum": 0, "maximum": MAX_WAIT,
            "description": "seconds to wait at most"}


def summarize(value: Any) -> Any:
    """``value`` (a message as a dict) with long arrays and byte strings summarized."""
    if isinstance(value, Mapping):
        return {k: summarize(v) for k, v in value.items()}
    if isinstance(value, bytes | bytearray | memoryview):
        if len(value) <= _SHORT_BYTES:
            return list(bytes(value))
        return f"<{len(value)} bytes>"
    if isinstance(value, list):
        if len(value) <= _SHORT_LIST:
            return [summarize(v) for v in value]
        text = f"<{len(value)} items; first 8: {json.dumps(summarize(value[:8]))}"
        if all(isinstance(v, int | float) and not isinstance(v, bool) for v in value):
            text += f"; min {min(value)}, max {max(value)}"
        return text + ">"
    return value


def _json(value: Any) -> str:
    return json.dumps(value, default=repr, allow_nan=True)


class RobotTools:
    """The tools of one robot, served through ``ros`` (see the module docstring)."""

    def __init__(self, ros: RosBase, options: Options | None = None,
                 on_change: Callable[[], Awaitable[None]] | None = None) -> None:
        """``on_change`` is awaited when a tool is withdrawn (the bridge refused it)."""
        self.ros = ros
        self.options = options or Options()
        self._on_change = on_change
        self._tools: dict[str, _Tool] = {}
        self._refused: set[tuple[str, str]] = set()
        self._publishers: dict[str, Publisher[Any]] = {}
        self._goals: dict[str, Any] = {}
        self._schemas: dict[str, tuple[dict[str, Any], dict[str, Any]]] = {}
        self._generic = self._generic_tools()
        self.presence = Presence(ros)

    # -- the list -------------------------------------------------------------------------------

    async def list_tools(self) -> list[types.Tool]:
        """The tools for the graph as it is now, held to the role (asked of the bridge)."""
        tools = dict(self._generic)
        if not await self._may_params():
            for name in PARAM_TOOLS:
                tools.pop(name)
        if self.options.read_only:
            tools = {n: t for n, t in tools.items()
                     if t.tool.annotations is not None and t.tool.annotations.read_only_hint}
        else:
            entries = await self._typed_entries()
            if not any(e.kind == "send_goal" for e in entries) and not self._goals:
                for name in GOAL_TOOLS:
                    tools.pop(name)
            for entry in entries:
                tool = self._typed_tool(entry, set(tools))
                tools[tool.tool.name] = tool
        listed, summarized, left_out = bound_listing((t.tool for t in tools.values()),
                                                     self.options.max_list)
        if summarized or left_out:
            finder = find_tools_tool(summarized, left_out)
            tools[FIND_TOOLS] = _Tool(finder, self._find_tools)
            listed.append(finder)
        self._tools = tools
        return listed

    async def _find_tools(self, args: dict[str, Any]) -> list[types.ContentBlock]:
        found = find_tools((t.tool for t in self._tools.values()), args, self.options.max_text)
        return self._text(found)

    async def _may_params(self) -> bool:
        """Whether the role may use some parameter: asking the bridge's may_params needs
        ``params`` on some name, so the question alone answers it (a bridge without it:
        yes, and its refusals say the rest)."""
        try:
            await self._ask_may("params", [])
        except Forbidden:
            return False
        except ServiceError:
            return True
        return True

    async def _typed_entries(self) -> list[_Typed]:
        graph, wait = self.ros.graph, self.options.timeout
        found: list[tuple[str, str, str]] = []
        for kind, listing in (("publish", graph.topics), ("call", graph.services),
                              ("send_goal", graph.actions)):
            # a role that may not list, a bridge without action listing: no such tools
            with contextlib.suppress(Forbidden, ServiceError):
                found += [(kind, x.name, x.type) for x in await listing(timeout=wait)]
        found = [f for f in found if f[2] and not internal(f[1])]
        allowed: set[tuple[str, str]] = set()
        for kind in _TYPED:
            names = [n for k, n, _ in found if k == kind]
            may = await self._may(kind, names)
            allowed.update((kind, n) for n in may)
        entries = []
        for kind, name, type_name in found:
            if (kind, name) not in allowed or (kind, name) in self._refused:
                continue
            try:
                (cls,) = await self.ros.load_types(type_name, timeout=wait)
            except (RosLibError, ValueError):
                continue  # a type the robot cannot describe: no typed tool for it
            entries.append(_Typed(kind, name, type_name, cls))
        return entries

    async def _may(self, kind: str, names: list[str]) -> list[str]:
        """The names the role may use for ``kind``, as the bridge says; all of them when it
        has no ``/rosapi/may_*`` (a refusal then withdraws the tool)."""
        if not names:
            return []
        try:
            return await self._ask_may(kind, names)
        except Forbidden:
            return []  # may not even ask: the role has the capability on no name
        except ServiceError:
            return names

    async def _ask_may(self, kind: str, names: list[str]) -> list[str]:
        allowed: list[str] = []
        for i in range(0, max(len(names), 1), _ASK_AT_ONCE):  # the bridge takes 10 000 a time
            answer = await self.ros.call_service(
                f"/rosapi/may_{_CAPABILITY[kind]}", "rosapi_msgs/srv/MayUse",
                {"names": names[i:i + _ASK_AT_ONCE]}, timeout=self.options.timeout)
            allowed += [n for n in answer.get("names", []) if isinstance(n, str)]
        return allowed

    def _schema(self, cls: Any) -> tuple[dict[str, Any], dict[str, Any]]:
        """A message type's schema and its ``$defs`` (for the tool schema's root), built once
        per type (the tools share them; nothing changes them)."""
        found = self._schemas.get(cls._type)
        if found is None:
            schema = message_schema(cls)
            found = self._schemas[cls._type] = (schema, schema.pop("$defs", {}))
        return found

    def _typed_tool(self, entry: _Typed, taken: set[str]) -> _Tool:
        name = tool_name(entry.kind, entry.name, taken)
        if entry.kind == "publish":
            schema, defs = self._schema(entry.cls)
            props = {"message": _body(schema, "the message to publish")}
            desc = f"Publish one message of type {quoted(entry.type_name)} on the topic "\
                   f"{quoted(entry.name)}."
            run = self._publisher(entry)
            required: tuple[str, ...] = ("message",)
        elif entry.kind == "call":
            schema, defs = self._schema(entry.cls.Request)
            props = {"request": _body(schema, "the request"), "timeout": _TIMEOUT}
            desc = f"Call the service {quoted(entry.name)} (type {quoted(entry.type_name)}); "\
                   "returns its response."
            run = self._caller(entry)
            required = ()
        else:
            schema, defs = self._schema(entry.cls.Goal)
            props = {"goal": _body(schema, "the goal"), "timeout": {
                **_TIMEOUT, "description": "seconds to wait for the result; the goal goes on "
                                           "after it (follow it with follow_goal)"}}
            desc = (f"Send a goal to the action {quoted(entry.name)} (type "
                    f"{quoted(entry.type_name)}); returns its result, or its goal id if it is "
                    "still running after the timeout.")
            run = self._goal_sender(entry)
            required = ()
        input_schema = _obj(props, required)
        if defs:
            input_schema["$defs"] = defs
        tool = types.Tool(name=name, description=f"{desc} {ROBOT_DATA}", input_schema=input_schema,
                          annotations=types.ToolAnnotations(read_only_hint=False))
        return _Tool(tool, self._guarded(entry, run))

    # -- calling --------------------------------------------------------------------------------

    async def call(self, name: str, arguments: dict[str, Any] | None,
                   progress: Progress | None = None, confirm: Confirm | None = None
                   ) -> types.CallToolResult:
        """Run tool ``name``; any failure is a tool error with the client's own text.
        ``progress`` hears how a long call (collect_topic) goes; ``confirm`` asks the user
        to allow a change when :attr:`Options.confirm` is on."""
        _PROGRESS.set(progress)
        if not self._tools:
            await self.list_tools()
        tool = self._tools.get(name)
        if tool is None:
            return _error(f"no tool {name!r} here (not in the graph, not allowed to this role, or "
                          "read-only; list the tools again: the graph may have changed)")
        annotations = tool.tool.annotations
        if self.options.confirm and annotations is not None and not annotations.read_only_hint:
            question = _cut(f"Allow {name} with {_json(arguments or {})}?", 500)
            try:
                allowed = confirm is not None and await confirm(question)
            except ConfirmationPending:
                raise
            except Exception as exc:  # the client could not ask (no elicitation)
                return _error(f"{name}: changes need the user's confirmation and it could not "
                              f"be asked ({type(exc).__name__}: {exc}); nothing was sent")
            if not allowed:
                return _error(f"{name}: not confirmed by the user; nothing was sent")
        away = self.presence.away
        try:
            content = await tool.run(dict(arguments or {}))
        except TimeoutError:
            return _error(f"{name}: no answer within the timeout", away())
        except RosLibError as exc:
            return _error(f"{type(exc).__name__}: {exc}", away())
        except (KeyError, TypeError, ValueError) as exc:
            return _error(f"{name}: bad arguments: {exc}")
        stale = self.presence.stale() if name in GRAPH_TOOLS else None
        if stale is not None:
            content = [types.TextContent(text=stale), *content]
        return types.CallToolResult(content=content)

    def _wait(self, args: Mapping[str, Any]) -> float:
        wait = args.get("timeout", self.options.timeout)
        if not isinstance(wait, int | float) or isinstance(wait, bool) or wait <= 0:
            raise ValueError(f"timeout must be a positive number of seconds, got {wait!r}")
        return min(float(wait), MAX_WAIT)

    def _text(self, value: Any) -> list[types.ContentBlock]:
        text = value if isinstance(value, str) else _json(value)
        return [types.TextContent(text=_cut(text, self.options.max_text))]

    def _guarded(self, entry: _Typed, run: Callable[[dict[str, Any]], Awaitable[Any]]
                 ) -> Callable[[dict[str, Any]], Awaitable[list[types.ContentBlock]]]:
        async def guarded(args: dict[str, Any]) -> list[types.ContentBlock]:
            try:
                return self._text(await run(args))
            except Forbidden:
                self._refused.add((entry.kind, entry.name))
                if self._on_change is not None:
                    await self._on_change()
                raise
        return guarded

    def _publisher(self, entry: _Typed) -> Callable[[dict[str, Any]], Awaitable[Any]]:
        async def publish(args: dict[str, Any]) -> Any:
            msg = from_wire(args.get("message") or {}, entry.cls, f"publish {entry.name}")
            pub = self._publishers.get(entry.name)
            if pub is None or pub.closed:
                pub = self.ros.advertise(entry.name, entry.cls)
                async with asyncio.timeout(self.options.timeout):
                    await pub
                self._publishers[entry.name] = pub
            async with asyncio.timeout(self.options.timeout):
                await pub.publish(msg)
            return f"published one {entry.type_name} on {entry.name}"
        return publish

    def _caller(self, entry: _Typed) -> Callable[[dict[str, Any]], Awaitable[Any]]:
        async def call(args: dict[str, Any]) -> Any:
            request = from_wire(args.get("request") or {}, entry.cls.Request,
                                f"call {entry.name}")
            response = await self.ros.call_service(entry.name, entry.cls, request,
                                                   timeout=self._wait(args))
            return summarize(response.to_json())
        return call

    def _goal_sender(self, entry: _Typed) -> Callable[[dict[str, Any]], Awaitable[Any]]:
        async def send(args: dict[str, Any]) -> Any:
            goal = from_wire(args.get("goal") or {}, entry.cls.Goal, f"goal {entry.name}")
            wait = self._wait(args)
            handle = await self.ros.send_goal(entry.name, entry.cls, goal)
            self._goals[handle.id] = handle
            return await self._follow(handle, wait)
        return send

    async def _follow(self, handle: Any, wait: float) -> Any:
        try:
            result = await handle.result(wait)
        except RosTimeoutError:
            return {"goal_id": handle.id, "status": handle.status.name,
                    "last_feedback": summarize(_plain(handle.last_feedback))}
        self._goals.pop(handle.id, None)
        out = {"goal_id": handle.id, "status": result.status.name,
               "result": summarize(_plain(result.values))}
        if result.text:
            out["text"] = result.text
        return out

    # -- the generic tools ------------------------------------------------------------------------

    def _generic_tools(self) -> dict[str, _Tool]:
        name_arg = {"type": "string", "description": "a ROS name, such as /chatter"}
        table: list[tuple[str, str, dict[str, Any], Callable[[dict[str, Any]], Awaitable[
            list[types.ContentBlock]]], bool]] = [
            ("list_topics", "The robot's topics and their types.", _obj({}),
             self._list_topics, True),
            ("list_services", "The robot's services and their types.", _obj({}),
             self._list_services, True),
            ("list_actions", "The robot's actions and their types.", _obj({}),
             self._list_actions, True),
            ("list_nodes", "The robot's nodes.", _obj({}), self._list_nodes, True),
            ("list_params", "The robot's parameters (/node:name).", _obj({}),
             self._list_params, True),
            ("describe_type", "The JSON Schema and the definition of a message, service or "
             "action type (pkg/msg/Name, pkg/srv/Name, pkg/action/Name).",
             _obj({"type": {"type": "string"}}, ("type",)), self._describe, True),
            ("read_topic", "The next message on a topic (waits at most timeout seconds). "
             "An Image or CompressedImage is returned as an image, scaled so its longer side "
             "is at most max_size pixels; long arrays are summarized.",
             _obj({"topic": name_arg, "timeout": _TIMEOUT,
                   "max_size": {"type": "integer", "minimum": 16, "maximum": 4096}},
                  ("topic",)), self._read_topic, True),
            ("collect_topic", "The messages of a topic for a while: at most seconds (up to "
             f"{MAX_WAIT:g}), max_messages (up to {MAX_COLLECT}) and max_bytes of summarized "
             "text, whichever comes first; progress is reported as they arrive.",
             _obj({"topic": name_arg, "seconds": _TIMEOUT,
                   "max_messages": {"type": "integer", "minimum": 1, "maximum": MAX_COLLECT},
                   "max_bytes": {"type": "integer", "minimum": 1}}, ("topic", "seconds")),
             self._collect, True),
            ("get_param", "A parameter's value (name: /node:param).",
             _obj({"name": {"type": "string"}}, ("name",)), self._get_param, True),
            ("set_param", "Set a parameter (name: /node:param) to a value.",
             _obj({"name": {"type": "string"}, "value": {}}, ("name", "value")),
             self._set_param, False),
            ("follow_goal", "Wait for the result of a goal this server sent (by goal_id).",
             _obj({"goal_id": {"type": "string"}, "timeout": _TIMEOUT}, ("goal_id",)),
             self._follow_goal, True),
            ("cancel_goal", "Cancel a goal this server sent (by goal_id).",
             _obj({"goal_id": {"type": "string"}}, ("goal_id",)), self._cancel_goal, False),
        ]
        return {name: _Tool(types.Tool(name=name, description=desc, input_schema=schema,
                                       annotations=types.ToolAnnotations(read_only_hint=ro)),
                            run)
                for name, desc, schema, run, ro in table}

    async def _pairs(self, listing: Awaitable[list[Any]]) -> list[types.ContentBlock]:
        return self._text([{"name": x.name, "type": x.type} for x in await listing])

    async def _list_topics(self, args: dict[str, Any]) -> list[types.ContentBlock]:
        return await self._pairs(self.ros.graph.topics(timeout=self.options.timeout))

    async def _list_services(self, args: dict[str, Any]) -> list[types.ContentBlock]:
        return await self._pairs(self.ros.graph.services(timeout=self.options.timeout))

    async def _list_actions(self, args: dict[str, Any]) -> list[types.ContentBlock]:
        return await self._pairs(self.ros.graph.actions(timeout=self.options.timeout))

    async def _list_nodes(self, args: dict[str, Any]) -> list[types.ContentBlock]:
        return self._text(await self.ros.graph.node_names(timeout=self.options.timeout))

    async def _list_params(self, args: dict[str, Any]) -> list[types.ContentBlock]:
        return self._text(await self.ros.graph.params(timeout=self.options.timeout))

    async def _describe(self, args: dict[str, Any]) -> list[types.ContentBlock]:
        (cls,) = await self.ros.load_types(args["type"], timeout=self.options.timeout)
        parts = {n: getattr(cls, n) for n in ("Request", "Response", "Goal", "Result",
                                              "Feedback") if hasattr(cls, n)}
        schemas = ({n: message_schema(p) for n, p in parts.items()} if parts
                   else message_schema(cls))  # type: ignore[arg-type]  # a message type
        return self._text({"type": cls._type, "definition": cls._definition,
                           "schema": schemas})

    async def _read_topic(self, args: dict[str, Any]) -> list[types.ContentBlock]:
        topic, wait = args["topic"], self._wait(args)
        type_name = await self._topic_type(topic)
        async with asyncio.timeout(wait):
            async with self.ros.subscribe(topic, type_name, buffer_size=1) as sub:
                msg = await sub.get()
        image_format = _IMAGE_TYPES.get(type_name)
        if image_format is not None:
            size = int(args.get("max_size", self.options.image_size))
            return image(msg, image_format, size, topic, type_name, self.options.max_pixels)
        summary = summarize(msg)
        if type_name == _CLOUD:
            summary["points"] = cloud_summary(msg)
        return self._text({"topic": topic, "type": type_name, "message": summary})

    async def _collect(self, args: dict[str, Any]) -> list[types.ContentBlock]:
        topic = args["topic"]
        seconds = self._wait({"timeout": args["seconds"]})
        most = min(int(args.get("max_messages", 100)), MAX_COLLECT)
        budget = min(int(args.get("max_bytes", self.options.max_text)), self.options.max_text)
        type_name = await self._topic_type(topic)
        report = _PROGRESS.get()
        got: list[dict[str, Any]] = []
        used, why = 0, "seconds"
        loop = asyncio.get_running_loop()
        start = loop.time()
        async with self.ros.subscribe(topic, type_name, buffer_size=most) as sub:
            while len(got) < most:
                left = seconds - (loop.time() - start)
                if left <= 0:
                    break
                try:
                    async with asyncio.timeout(left):
                        msg = await sub.get()
                except TimeoutError:
                    break
                entry = {"t": round(loop.time() - start, 3), "message": summarize(msg)}
                used += len(_json(entry))
                if used > budget:
                    why = "max_bytes"
                    break
                got.append(entry)
                if report is not None:
                    await report(len(got), float(most),
                                 f"{len(got)} messages in {entry['t']} s")
            else:
                why = "max_messages"
        return self._text({"topic": topic, "type": type_name, "count": len(got),
                           "stopped_by": why, "messages": got})

    async def _topic_type(self, topic: str) -> str:
        type_name = await self.ros.graph.topic_type(topic, timeout=self.options.timeout)
        if not type_name:
            raise ValueError(f"topic {topic} is not in the ROS graph (see list_topics)")
        return type_name

    async def _get_param(self, args: dict[str, Any]) -> list[types.ContentBlock]:
        unset = object()  # no JSON value is this: the parameter is not set
        value = await self.ros.graph.get_param(args["name"], unset, timeout=self.options.timeout)
        if value is unset:
            raise ValueError(f"no parameter {args['name']} (not declared on the node; see "
                             "list_params)")
        return self._text(value)

    async def _set_param(self, args: dict[str, Any]) -> list[types.ContentBlock]:
        await self.ros.graph.set_param(args["name"], args["value"], timeout=self.options.timeout)
        return self._text(f"set {args['name']}")

    def _goal(self, args: dict[str, Any]) -> Any:
        handle = self._goals.get(args["goal_id"])
        if handle is None:
            raise ValueError(f"no running goal {args['goal_id']!r} sent by this server")
        return handle

    async def _follow_goal(self, args: dict[str, Any]) -> list[types.ContentBlock]:
        return self._text(await self._follow(self._goal(args), self._wait(args)))

    async def _cancel_goal(self, args: dict[str, Any]) -> list[types.ContentBlock]:
        handle = self._goal(args)
        await handle.cancel()
        return self._text(f"cancel of goal {handle.id} sent")


def _body(schema: dict[str, Any], what: str) -> dict[str, Any]:
    return {**schema, "description": f"{what}: {schema.get('description', '')}"}


def _plain(value: Any) -> Any:
    return value.to_json() if hasattr(value, "to_json") else value


def _cut(text: str, limit: int) -> str:
    if len(text) <= limit:
        return text
    return text[:limit] + f"\n... [cut: {len(text)} characters in all]"


def _error(text: str, away: str | None = None) -> types.CallToolResult:
    text = text if away is None else f"{text}; {away}"
    return types.CallToolResult(content=[types.TextContent(text=text)], is_error=True)
