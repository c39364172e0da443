"""The sans-I/O core read like the spec: ops parse, serialize and fail as PROTOCOL.md says."""

from __future__ import annotations

import json
from typing import Any, ClassVar

import pytest

from rosbridge_core.protocol.ops import (
    Advertise,
    AdvertiseService,
    CallService,
    Fragment,
    Publish,
    ServiceResponse,
    Status,
    Subscribe,
    Unsubscribe,
    encode,
    parse_op,
    to_obj,
)
from roslibpy_lite.exceptions import RemoteProtocolError


def test_publish_parses_into_a_value() -> None:
    """A publish op becomes a Publish value with its topic, msg and id."""
    op = parse_op({"op": "publish", "topic": "/a", "msg": {"data": 1}, "id": "p1"})
    assert op == Publish(topic="/a", msg={"data": 1}, id="p1")


def test_subscribe_defaults_follow_the_spec() -> None:
    """Optional subscribe fields take the spec's defaults when absent or null."""
    op = parse_op({"op": "subscribe", "topic": "/a", "fragment_size": None})
    assert op == Subscribe(topic="/a")
    assert (op.throttle_rate, op.queue_length, op.compression) == (0, 0, "none")


def test_subscribe_accepts_every_option() -> None:
    """throttle_rate, queue_length, fragment_size and compression are carried through."""
    op = parse_op({"op": "subscribe", "topic": "/a", "type": "std_msgs/String", "id": 7,
                   "throttle_rate": 100, "queue_length": 5, "fragment_size": 1000,
                   "compression": "cbor"})
    assert op == Subscribe("/a", "std_msgs/String", 7, 100, 5, 1000, "cbor")


def test_call_service_takes_args_as_object_or_list() -> None:
    """call_service args may be an object or a list (zipped onto fields by the server)."""
    obj = parse_op({"op": "call_service", "service": "/s", "args": {"x": 1}})
    lst = parse_op({"op": "call_service", "service": "/s", "args": [1, 2], "timeout": 2})
    assert isinstance(obj, CallService) and obj.args == {"x": 1}
    assert isinstance(lst, CallService) and lst.args == [1, 2] and lst.timeout == 2.0


def test_unknown_fields_are_ignored() -> None:
    """Extra fields that stock clients send do not make an op invalid."""
    op = parse_op({"op": "advertise", "topic": "/a", "type": "std_msgs/String", "extra": 1})
    assert op == Advertise(topic="/a", type="std_msgs/String")


@pytest.mark.parametrize(
    ("frame", "words"),
    [
        ({"topic": "/a"}, "missing field 'op'"),
        ({"op": 5}, "field 'op' must be a string"),
        ({"op": "teleport"}, "unknown op 'teleport'"),
        ({"op": "subscribe"}, "subscribe: missing field 'topic'"),
        ({"op": "subscribe", "topic": 3}, "field 'topic' must be a non-empty string, got a number"),
        ({"op": "subscribe", "topic": "/a", "queue_length": -1}, "'queue_length' must be an integer >= 0"),
        ({"op": "subscribe", "topic": "/a", "queue_length": True}, "got a boolean"),
        ({"op": "subscribe", "topic": "/a", "compression": "zip"}, "'compression' must be one of"),
        ({"op": "publish", "topic": "/a", "msg": [1]}, "'msg' must be an object, got a list"),
        ({"op": "call_service", "service": "/s", "timeout": 0}, "'timeout' must be a number of seconds > 0"),
        ({"op": "service_response", "service": "/s"}, "missing field 'result'"),
        ({"op": "fragment", "id": "f", "data": "x", "num": 2, "total": 2}, "must be less than 'total'"),
    ],
)
def test_bad_ops_name_the_field_and_the_expectation(frame: dict[str, Any], words: str) -> None:
    """Every invalid op raises RemoteProtocolError whose message names what was wrong."""
    with pytest.raises(RemoteProtocolError) as info:
        parse_op(frame)
    assert words in str(info.value)


def test_errors_carry_the_op_and_id() -> None:
    """A parse error keeps the request's op and id, so the server can answer the sender."""
    with pytest.raises(RemoteProtocolError) as info:
        parse_op({"op": "subscribe", "id": "sub-9", "topic": ""})
    assert info.value.op == "subscribe" and info.value.id == "sub-9"


def test_non_object_frames_are_refused() -> None:
    """A frame that is not a JSON object is not an op."""
    with pytest.raises(RemoteProtocolError, match="must be a JSON object, got a list"):
        parse_op([{"op": "publish"}])


def test_encode_leaves_absent_fields_out_and_puts_op_first() -> None:
    """Serialization writes op first and omits fields that are None."""
    text = encode(ServiceResponse(service="/s", result=True, values={"ok": 1}, id="c1"))
    assert text == '{"op":"service_response","service":"/s","result":true,"values":{"ok":1},"id":"c1"}'


def test_encode_turns_non_finite_floats_into_null() -> None:
    """NaN and infinities go out as JSON null, since JSON has no NaN."""
    text = encode(Publish(topic="/a", msg={"v": [1.0, float("nan"), float("inf")]}))
    assert json.loads(text)["msg"] == {"v": [1.0, None, None]}


@pytest.mark.parametrize(
    "op",
    [
        Advertise("/a", "std_msgs/msg/String", "a1", True, 5),
        Subscribe("/a", "std_msgs/msg/String", "s1", 10, 2, 100, "cbor-raw"),
        Unsubscribe("/a", "s1"),
        CallService("/s", [1, 2], "mult_msgs/srv/MultFloats", 3, 1.5),
        AdvertiseService("/s", "std_srvs/srv/SetBool"),
        Fragment("f", "abc", 0, 3),
        Status("error", "bad", "x"),
    ],
)
def test_ops_round_trip(op: Any) -> None:
    """Parsing what encode wrote gives the same value back."""
    assert parse_op(json.loads(encode(op))) == op
    assert to_obj(op)["op"] == op.OP


def test_every_op_declares_its_facts_on_its_class() -> None:
    """Each op's TARGET names one of its own fields, every op that needs a capability names
    what it acts on, and a field whose kind is not declared is refused where the op is."""
    from dataclasses import dataclass, fields
    from typing import get_args

    from rosbridge_core.protocol import kinds, ops

    for cls in get_args(ops.Op):
        names = {f.name for f in fields(cls)}
        assert cls.TARGET is None or cls.TARGET in names, cls
        assert cls.NEEDS is None or cls.TARGET is not None, cls
        assert not cls.ACKED or cls.NEEDS is not None, cls

    @dataclass(frozen=True, slots=True)
    class Sloppy(ops._OpFacts):
        OP: ClassVar[str] = "sloppy"
        topic: str

    with pytest.raises(TypeError, match=r"Sloppy\.topic: annotate it with its kind"):
        kinds._rules_of(Sloppy)


def test_a_refused_call_or_goal_gets_the_answer_a_stock_peer_waits_for() -> None:
    """A refused call_service is answered by a failed service_response, a refused goal with
    an id by an aborted action_result; other ops by the status error alone."""
    from rosbridge_core.protocol import ops

    call = ops.CallService("/s", id="c1").refusal("forbidden")
    assert call == ops.ServiceResponse("/s", False, "call_service: forbidden", "c1")
    goal = ops.SendActionGoal("/a", "x/action/Y", id="g1").refusal("forbidden")
    assert goal == ops.ActionResultOp("g1", "/a", False, "send_action_goal: forbidden", 6)
    assert ops.SendActionGoal("/a", "x/action/Y").refusal("forbidden") is None
    assert ops.Subscribe("/t").refusal("forbidden") is None
