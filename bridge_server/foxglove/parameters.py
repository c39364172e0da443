"""A Foxglove client's parameters: ``getParameters``, ``setParameters`` and the updates it
follows, as :class:`ParameterOps`, a part of
:class:`~bridge_server.foxglove.session.FoxgloveSession`, with the spec's value encoding
(:func:`parameter_entry`, :func:`from_wire`)."""

from __future__ import annotations

import asyncio
import base64
import binascii
import math
from typing import Any

from bridge_server.foxglove import ops
from bridge_server.foxglove.base import SessionBase
from rosbridge_core.interfaces import BridgeError
from rosbridge_core.protocol.names import absolute_name
from rosbridge_core.security.permissions import PARAMETER_LISTING

__all__ = ["ParameterOps", "from_wire", "parameter_entry", "split_name"]


class ParameterOps(SessionBase):
    """The parameter ops of a Foxglove client, and the updates it is sent."""

    def parameters_changed(self, changed: list[tuple[str, Any]]) -> None:
        """Parameters changed in ROS: tell the client of those it follows."""
        names = self.parameter_names
        if names is None:
            return
        shown = [(n, v) for n, v in changed if (not names or n in names)
                 and self.gate.forbids("params", ":".join(split_name(n))) is None]
        if shown:
            self.send_text(ops.json_frame("parameterValues",
                                           parameters=[parameter_entry(n, v) for n, v in shown]))

    # -- parameters ----------------------------------------------------------------------------

    def _get_parameters(self, op: ops.GetParameters) -> None:
        for name in op.names:
            split_name(name)  # a name that is not /node.param is refused now
        if op.names or self.gate.allowed(op, *PARAMETER_LISTING):
            self.spawn(self._answer_parameters(list(op.names), op.id))
        elif op.id is not None:  # refused (the client was told): no values for the id
            self.send_text(ops.json_frame("parameterValues", parameters=[], id=op.id))

    async def _answer_parameters(self, names: list[str], request_id: str | None) -> None:
        if not names:
            names = await self._all_parameter_names()
        found: list[dict[str, Any]] = []
        for name, value in zip(names, await asyncio.gather(
                *(self._get_one(n) for n in names)), strict=True):
            if value is not _MISSING:
                found.append(parameter_entry(name, value))
        self.send_text(ops.json_frame("parameterValues", parameters=found, id=request_id))

    async def _all_parameter_names(self) -> list[str]:
        nodes = [f"{ns.rstrip('/')}/{n}" for n, ns in self.graph.node_names()]

        async def of(node: str) -> list[str]:
            try:
                names = await self.graph.parameter_names(node, 2.0)
            except Exception:  # a node without parameter services, or gone
                return []
            return [f"{node}.{p}" for p in names
                    if self.gate.forbids("params", f"{node}:{p}") is None]

        return [name for names in await asyncio.gather(*(of(n) for n in nodes))
                for name in names]

    async def _get_one(self, name: str) -> Any:
        node, param = split_name(name)
        why = self.gate.forbids("params", f"{node}:{param}")
        if why is not None:
            self.error(f"getParameters: {name}: forbidden: {why}")
            return _MISSING
        try:
            is_set, value = await self.graph.get_parameter(node, param)
        except (TimeoutError, LookupError, BridgeError) as exc:
            self.error(f"getParameters: {name}: node {node} did not answer ({exc or 'timeout'})")
            return _MISSING
        return value if is_set else _MISSING

    def _set_parameters(self, op: ops.SetParameters) -> None:
        for name, _, _ in op.parameters:
            split_name(name)
        self.spawn(self._run_set(op))

    async def _run_set(self, op: ops.SetParameters) -> None:
        done: list[str] = []
        for name, raw, kind in op.parameters:
            node, param = split_name(name)
            why = self.gate.forbids("params", f"{node}:{param}")
            if why is not None:
                self.error(f"setParameters: {name}: forbidden: {why}")
                continue
            try:
                value = from_wire(raw, kind)
                ok, reason = await self.graph.set_parameter(node, param, value)
            except (ValueError, TypeError) as exc:
                self.error(f"setParameters: {name}: {exc}")
                continue
            except (TimeoutError, LookupError, BridgeError) as exc:
                self.error(f"setParameters: {name}: node {node} did not answer "
                           f"({exc or 'timeout'})")
                continue
            if not ok:
                self.error(f"setParameters: {name}: the node refused: {reason or 'no reason'}")
                continue
            done.append(name)
        if op.id is not None:
            await self._answer_parameters(done, op.id) if done else self.send_text(
                ops.json_frame("parameterValues", parameters=[], id=op.id))

    def _follow_parameters(self, op: ops.SubscribeParameterUpdates) -> None:
        if not self.gate.allowed(op, *PARAMETER_LISTING):
            return
        current = self.parameter_names
        if not op.names:
            self.parameter_names = set()
        elif current is None:
            self.parameter_names = set(op.names)
        elif current:
            current.update(op.names)
        self.hub.update_watches()

    def _unfollow_parameters(self, op: ops.UnsubscribeParameterUpdates) -> None:
        current = self.parameter_names
        if not op.names or current is None:
            self.parameter_names = None
        else:
            current.difference_update(op.names)
            if not current:
                self.parameter_names = None
        self.hub.update_watches()


_MISSING = object()


def split_name(name: str) -> tuple[str, str]:
    """``/node.param`` as (``/node``, ``param``): node names have no dots, parameters may."""
    node, dot, param = name.partition(".")
    if not dot or not node or not param:
        raise BridgeError(f"parameter {name!r}: expected '/node_name.parameter_name'")
    return absolute_name(node), param


def parameter_entry(name: str, value: Any) -> dict[str, Any]:
    """One entry of ``parameterValues`` from a Graph parameter value, as the spec has it: a
    byte array as base64 text typed ``byte_array``, a double typed ``float64``, a non-empty
    double array typed ``float64_array`` (an empty one cannot be told from other empty
    arrays), ``None`` (unset) with no value. JSON has no NaN or infinity: a double that is
    one is its text (``"nan"``, ``"inf"``, ``"-inf"``) and the value is not typed as a
    number, in an array too."""
    if isinstance(value, bytes | bytearray):
        return {"name": name, "value": base64.b64encode(value).decode(), "type": "byte_array"}
    if isinstance(value, float):
        if not math.isfinite(value):
            return {"name": name, "value": str(value)}
        return {"name": name, "value": value, "type": "float64"}
    if isinstance(value, list) and value and all(isinstance(v, float) for v in value):
        if not all(math.isfinite(v) for v in value):
            return {"name": name, "value": [v if math.isfinite(v) else str(v) for v in value]}
        return {"name": name, "value": value, "type": "float64_array"}
    if value is None:
        return {"name": name}
    return {"name": name, "value": value}


def from_wire(value: Any, kind: str | None) -> Any:
    """A ``setParameters`` value as the Graph takes it."""
    if value is None:
        return None
    if kind == "byte_array":
        if not isinstance(value, str):
            raise ValueError("a byte_array value must be a base64 string")
        try:
            return base64.b64decode(value, validate=True)
        except binascii.Error as exc:
            raise ValueError(f"a byte_array value is not base64: {exc}") from None
    if kind == "float64":
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"a float64 value must be a number, got {type(value).__name__}")
        return float(value)
    if kind == "float64_array":
        if not isinstance(value, list) or not all(
                isinstance(v, int | float) and not isinstance(v, bool) for v in value):
            raise ValueError("a float64_array value must be a list of numbers")
        return [float(v) for v in value]
    return value
