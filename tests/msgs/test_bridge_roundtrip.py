"""Every generated type, default and populated, goes client -> bridge -> rclpy -> bridge -> client unchanged."""

from __future__ import annotations

import importlib
import re
from typing import Any

import pytest

from msgs.runtime import Message, available_types, lookup_message
from tests.helpers import WireClient, async_wait_until

pytest.importorskip("rclpy", reason="the round trip needs rclpy on the ROS side")

_SEQ = re.compile(r"sequence<(.+?)(?:, (\d+))?>$")
_FIXED = re.compile(r"(.+)\[(\d+)\]$")
_BOUNDED_STR = re.compile(r"w?string<(\d+)>$")
_BYTES = ("uint8", "octet")
_INTS = {"int8", "int16", "int32", "int64", "uint8", "uint16", "uint32", "uint64", "octet", "char"}


def _value(idl: str, salt: int) -> Any:
    """A non-default wire value for a field of rclpy type spelling ``idl``."""
    fixed = _FIXED.match(idl)
    seq = _SEQ.match(idl)
    if fixed or seq:
        inner = (fixed or seq).group(1)  # type: ignore[union-attr]
        count = int(fixed.group(2)) if fixed else 2
        if seq and seq.group(2):
            count = min(count, int(seq.group(2)))
        return [_value(inner, salt + i) for i in range(count)]
    if idl == "boolean":
        return True
    if idl in _INTS:
        return 1 + salt % 100
    if idl in ("float", "double"):
        return 0.5 + salt
    if idl in ("string", "wstring"):
        return f"v{salt}"
    bounded = _BOUNDED_STR.match(idl)
    if bounded:
        return f"v{salt}"[: int(bounded.group(1))]
    return _populated(lookup_message(idl), salt + 1)


def _populated(cls: type[Message], salt: int = 0) -> dict[str, Any]:
    """Every field of ``cls`` set to a non-default value, in wire form."""
    return {name: _value(idl, salt + i) for i, (name, idl) in enumerate(cls._fields_and_types.items())}


def _rclpy_class(type_name: str) -> Any:
    pkg, kind, name = type_name.split("/")
    return getattr(importlib.import_module(f"{pkg}.{kind}"), name)


MESSAGE_TYPES = [t for t in available_types() if "/msg/" in t]


async def test_every_message_type_round_trips_through_the_bridge(
    ws_connect: Any, ros_node: Any, topic: str
) -> None:
    """Default and populated instances of every generated message come back from rclpy equal."""
    client: WireClient = await ws_connect()
    cases: list[tuple[str, str, str, type[Message]]] = []
    endpoints: list[tuple[Any, Any]] = []
    for i, type_name in enumerate(MESSAGE_TYPES):
        rclpy_cls = _rclpy_class(type_name)
        inbound, outbound = f"{topic}/m{i}/in", f"{topic}/m{i}/out"
        pub = ros_node.create_publisher(rclpy_cls, outbound, 10)
        sub = ros_node.create_subscription(rclpy_cls, inbound, pub.publish, 10)
        endpoints.append((pub, sub))
        cases.append((type_name, inbound, outbound, lookup_message(type_name)))
        await client.send({"op": "advertise", "topic": inbound, "type": type_name})
        await client.send({"op": "subscribe", "topic": outbound, "type": type_name})

    def matched() -> bool:
        # matched endpoint to endpoint (the graph may list a peer before DDS has matched it,
        # and a message sent in between is lost)
        return all(
            sub.get_publisher_count() >= 1 and pub.get_subscription_count() >= 1
            for pub, sub in endpoints
        )

    await async_wait_until(matched, timeout=60, what="bridge endpoints for every type")

    for type_name, inbound, outbound, cls in cases:
        for sent in ({}, _populated(cls)):
            want = cls.from_json(sent)
            # The reader's matched count says nothing of the bridge's writer, which may match
            # the reader a moment later (a message sent before is lost): send again until the
            # echo comes, and skip echoes of earlier sends.
            for attempt in range(15):
                await client.send({"op": "publish", "topic": inbound, "msg": sent})
                try:
                    got = await client.expect(
                        lambda m: bool(cls.from_json(m["msg"]) == want),  # noqa: B023 - called before the loop moves on
                        op="publish", topic=outbound, timeout=1)
                    break
                except AssertionError:
                    if attempt == 14:
                        raise
            assert cls.from_json(got["msg"]) == want, type_name
