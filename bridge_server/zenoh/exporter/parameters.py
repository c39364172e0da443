"""Node parameters: a relay's request is a query run by the Graph's parameter methods (names
the robot's relay policy hides are left out of a listing)."""

from __future__ import annotations

from typing import Any

import zenoh

from bridge_server.zenoh import keys
from bridge_server.zenoh.exporter.base import json_bytes
from bridge_server.zenoh.exporter.policy import RelayPolicy
from bridge_server.zenoh.keys import ParamRequest
from bridge_server.zenoh.link import answering

__all__ = ["Parameters"]


class Parameters(RelayPolicy):
    """The exporter's part that answers relays' parameter requests."""

    def _answer_param(self, query: zenoh.Query) -> None:
        self._spawn(self._param(query))

    async def _param(self, query: zenoh.Query) -> None:
        with answering(query):
            node = keys.name_of(str(query.key_expr), 2)
            kind = "error"
            try:
                req = ParamRequest.decode(query.payload.to_bytes() if query.payload else b"")
                answer: Any
                if req.op != "names":
                    refused = self.refusal("params", f"{node}:{req.name}")
                    if refused is not None:
                        raise PermissionError(refused)
                if req.op == "names":
                    role = self.policy()  # names the policy hides are left out, unlogged
                    answer = [n for n in await self.graph.parameter_names(node, req.timeout)
                              if role is not None and role.allows("params", f"{node}:{n}")]
                elif req.op == "get":
                    answer = await self.graph.get_parameter(node, req.name)
                else:
                    answer = await self.graph.set_parameter(node, req.name, req.value)
                query.reply(query.key_expr, req.answer(answer))
                return
            except TimeoutError as exc:
                kind, text = "timeout", str(exc) or f"node {node} did not answer in time"
            except LookupError as exc:
                kind, text = "lookup", str(exc)
            except ValueError as exc:
                kind, text = "value", str(exc)
            except PermissionError as exc:
                kind, text = "forbidden", str(exc)
            except Exception as exc:  # the relay's caller gets the text, as the bridge's does
                text = str(exc)
            query.reply_err(json_bytes({"kind": kind, "text": text}))
