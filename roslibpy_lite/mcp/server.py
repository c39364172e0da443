"""The MCP server: :class:`~roslibpy_lite.mcp.tools.RobotTools` behind the SDK's low-level
``Server``, over stdio or streamable HTTP."""

from __future__ import annotations

import hashlib
import json
import logging
import secrets
from collections import OrderedDict
from typing import Any

import mcp_types as types
from mcp.server.context import ServerRequestContext
from mcp.server.lowlevel import NotificationOptions, Server
from mcp.server.request_state import RequestStateBoundary, RequestStateSecurity
from mcp.shared.exceptions import NoBackChannelError

from .. import __version__
from ..ros import RosBase
from .door import HttpDoor, http_app
from .tools import ConfirmationPending, Options, RobotTools

__all__ = ["build_server", "serve_http", "serve_stdio"]

INSTRUCTIONS = (
    "Tools for one ROS 2 robot, reached through a rosbridge server with this server's own "
    "token: you may do only what that token's role allows (tools it does not allow are not "
    "listed). Start with list_topics / list_services / list_actions; describe_type shows a "
    "type's fields. Typed tools (publish__*, call__*, send_goal__*) take the message as the "
    "robot defines it; a field that does not fit is named in the error."
)


_CONFIRM_KEY = "confirm"
_CONFIRM_FORM: Any = {"type": "object", "required": ["confirm"], "properties": {
    "confirm": {"type": "boolean", "title": "Allow this change on the robot"}}}


_ASKED_AT_ONCE = 64
"""The most confirmations asked in a call's answer (2026-07-28) awaiting their retry."""
_ASKED_FOR = 600.0
"""How long (seconds) such a question may be answered: the sealed request state's life."""

log = logging.getLogger("roslibpy_lite.mcp")


def _allowed(answer: types.ElicitResult) -> bool:
    return answer.action == "accept" and bool((answer.content or {}).get("confirm"))


def _call_key(params: types.CallToolRequestParams) -> str:
    """The tool and its arguments, as a confirmation is asked about them."""
    text = json.dumps([params.name, params.arguments or {}], sort_keys=True, default=repr)
    return hashlib.sha256(text.encode("utf-8", "surrogatepass")).hexdigest()


class _Asked:
    """The confirmations this server asked in a call's answer, each by a one-time id sent as
    the answer's request state (sealed by the SDK's ``RequestStateBoundary``): only a retry
    carrying one, for the same tool and arguments, brings the user's answer. An answer sent
    unasked (``input_responses`` on a first call) is not one."""

    def __init__(self) -> None:
        self._asked: OrderedDict[str, str] = OrderedDict()

    def ask(self, params: types.CallToolRequestParams) -> str:
        """A new question's id, kept until answered (the oldest dropped past the bound)."""
        asked_id = secrets.token_urlsafe(18)
        self._asked[asked_id] = _call_key(params)
        while len(self._asked) > _ASKED_AT_ONCE:
            self._asked.popitem(last=False)
        return asked_id

    def answer(self, params: types.CallToolRequestParams) -> Any:
        """The user's answer this retry carries to a question asked of it, else ``None``."""
        given = (params.input_responses or {}).get(_CONFIRM_KEY)
        if given is None:
            return None
        key = self._asked.pop(params.request_state, None) if params.request_state else None
        if key != _call_key(params):
            log.warning("tools/call %s: a confirmation answer that was not asked for (or was "
                        "for other arguments) is ignored; the user is asked", params.name)
            return None
        return given


def build_server(ros: RosBase, options: Options | None = None) -> Server[Any]:
    """An MCP ``Server`` whose tools are the robot's, served through ``ros``."""
    sessions: list[Any] = []

    async def changed() -> None:
        for session in list(sessions):
            try:
                await session.send_tool_list_changed()
            except Exception:  # a session gone: it will not list again anyway
                sessions.remove(session)

    robot = RobotTools(ros, options, on_change=changed)
    asked = _Asked()

    async def list_tools(ctx: ServerRequestContext[Any],
                         params: types.PaginatedRequestParams | None) -> types.ListToolsResult:
        session = getattr(ctx, "session", None)
        if session is not None and session not in sessions:
            sessions.append(session)
        return types.ListToolsResult(tools=await robot.list_tools())

    async def call_tool(ctx: ServerRequestContext[Any], params: types.CallToolRequestParams
                        ) -> types.CallToolResult | types.InputRequiredResult:
        answered = asked.answer(params)

        async def confirm(question: str) -> bool:
            if isinstance(answered, types.ElicitResult):  # the retry, with the user's answer
                return _allowed(answered)
            try:
                return _allowed(await ctx.session.elicit_form(question, _CONFIRM_FORM))
            except NoBackChannelError:  # 2026-07-28: ask in the answer, the client retries
                raise ConfirmationPending(question) from None

        try:
            return await robot.call(params.name, params.arguments,
                                    ctx.session.report_progress, confirm)
        except ConfirmationPending as pending:
            ask = types.ElicitRequest(params=types.ElicitRequestFormParams(
                message=pending.question, requested_schema=_CONFIRM_FORM))
            return types.InputRequiredResult(input_requests={_CONFIRM_KEY: ask},
                                             request_state=asked.ask(params))

    server: Server[Any] = Server("roslibpy-lite", version=__version__,
                                 instructions=INSTRUCTIONS, on_list_tools=list_tools,
                                 on_call_tool=call_tool)
    server.middleware.append(RequestStateBoundary(
        RequestStateSecurity.ephemeral(ttl=_ASKED_FOR), default_audience="roslibpy-lite"))
    server.robot = robot  # type: ignore[attr-defined]
    return server


def _init_options(server: Server[Any]) -> Any:
    return server.create_initialization_options(
        notification_options=NotificationOptions(tools_changed=True))


async def serve_stdio(ros: RosBase, options: Options | None = None) -> None:
    """Serve MCP over this process's stdin and stdout until the client goes."""
    from mcp.server.stdio import stdio_server

    server = build_server(ros, options)
    async with stdio_server() as (read, write):
        await server.run(read, write, _init_options(server))


async def serve_http(ros: RosBase, options: Options | None = None,
                     door: HttpDoor | None = None) -> None:
    """Serve MCP over streamable HTTP at ``door.url`` until cancelled, behind ``door``'s
    token, TLS and Host checks (:mod:`roslibpy_lite.mcp.door`; the default door: loopback,
    port 8765, no token, which :meth:`HttpDoor.refusal` refuses unless ``no_auth``)."""
    import uvicorn

    door = door or HttpDoor()
    refusal = door.refusal()
    if refusal is not None:
        raise ValueError(refusal)
    for warning in door.warnings():
        log.warning("%s", warning)
    app = http_app(build_server(ros, options), door)
    config = uvicorn.Config(app, host=door.host, port=door.port, log_level="warning",
                            lifespan="on", ssl_certfile=door.certfile, ssl_keyfile=door.keyfile)
    log.info("MCP over streamable HTTP at %s", door.url)
    await uvicorn.Server(config).serve()
