"""parse_op's fast path for the frame a server sends most (a publish of op, topic and msg):
taken for that shape only, and never more lenient than the rules it skips."""

from __future__ import annotations

from typing import Any

import pytest

from rosbridge_core.protocol import ops
from rosbridge_core.protocol.ops import Publish, parse_op
from roslibpy_lite.exceptions import RemoteProtocolError


def test_a_servers_publish_is_parsed_without_the_rules_table(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A publish of exactly op, topic and msg parses to the same value with the rules table
    emptied; a publish with any other field still needs the table."""
    frame = {"op": "publish", "topic": "/a", "msg": {"data": 1}}
    expected = parse_op(frame)
    monkeypatch.setattr(ops, "_RULES", {})
    assert parse_op(frame) == expected == Publish(topic="/a", msg={"data": 1})
    with pytest.raises(RemoteProtocolError, match="unknown op 'publish'"):
        parse_op({**frame, "id": "p1"})


class _Name(str):
    """A str subclass: the rules accept it, the fast path leaves it to them."""


@pytest.mark.parametrize(
    ("frame", "outcome"),
    [
        ({"op": "publish", "topic": "", "msg": {}}, "'topic' must be a non-empty string"),
        ({"op": "publish", "topic": 3, "msg": {}}, "'topic' must be a non-empty string"),
        ({"op": "publish", "topic": "/a", "msg": [1]}, "'msg' must be an object, got a list"),
        ({"op": "publish", "topic": "/a", "msg": None}, "missing field 'msg'"),
        ({"op": "publish", "topic": "/a", "latch": True}, "missing field 'msg'"),
        ({"op": "publish", "topic": _Name("/a"), "msg": {}}, Publish(topic="/a", msg={})),
    ],
)
def test_the_fast_path_refuses_what_the_rules_refuse(frame: dict[str, Any],
                                                     outcome: str | Publish) -> None:
    """A three-field publish the fast path cannot take gets the rules' verdict: the same
    error naming the field, or the same value."""
    if isinstance(outcome, Publish):
        assert parse_op(frame) == outcome
        return
    with pytest.raises(RemoteProtocolError) as info:
        parse_op(frame)
    assert outcome in str(info.value)
