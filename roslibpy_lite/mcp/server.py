"""The MCP server: :class:`~roslibpy_lite.mcp.tools.RobotTools` behind the SDK's low-level
``Server``, over stdio or streamable HTTP."""

from __future__ import annotations

from typing import Any

import mcp_types as types
from mcp.server.context import ServerRequestContext
from mcp.server.lowlevel import NotificationOptions, Server
from mcp.shared.exceptions import NoBackChannelError

from .. import __version__
from ..ros import RosBase
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


def _allowed(answer: types.ElicitResult) -> bool:
    return answer.action == "accept" and bool((answer.content or {}).get("confirm"))


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

    async def list_tools(ctx: ServerRequestContext[Any],
                         params: types.PaginatedRequestParams | None) -> types.ListToolsResult:
        session = getattr(ctx, "session", None)
        if session is not None and session not in sessions:
            sessions.append(session)
        return types.ListToolsResult(tools=await robot.list_tools())

    async def call_tool(ctx: ServerRequestContext[Any], params: types.CallToolRequestParams
                        ) -> types.CallToolResult | types.InputRequiredResult:
        answered = (params.input_responses or {}).get(_CONFIRM_KEY)

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
            return types.InputRequiredResult(input_requests={_CONFIRM_KEY: ask})

    server: Server[Any] = Server("roslibpy-lite", version=__version__,
                                 instructions=INSTRUCTIONS, on_list_tools=list_tools,
                                 on_call_tool=call_tool)
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


async def serve_http(ros: RosBase, options: Options | None = None, *,
                     host: str = "127.0.0.1", port: int = 8765) -> None:
    """Serve MCP over streamable HTTP at ``http://host:port/mcp`` until cancelled."""
    import uvicorn

    app = build_server(ros, options).streamable_http_app(host=host)
    config = uvicorn.Config(app, host=host, port=port, log_level="warning", lifespan="on")
    await uvicorn.Server(config).serve()
