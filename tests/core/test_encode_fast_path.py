"""ops.encode's fast paths: each op class's field names read once (not dataclasses.fields()
per op) and one JSON encoder made once (not one per json.dumps call), with the same text."""

from __future__ import annotations

import json
from typing import Any, get_args

import pytest

from rosbridge_core.protocol import ops
from rosbridge_core.protocol.ops import CallService, Publish, ServiceResponse, Status

NAN = float("nan")
"""One NaN for every op (a NaN equals only itself, by identity, in a dict's comparison)."""


def _ops() -> list[Any]:
    """One op of each kind used most, with absent fields, bytes and a NaN among them."""
    return [Publish(topic="/a", msg={"data": NAN, "raw": b"\x01\x02"}),
            CallService(service="/s", args={"data": True}, id="c1"),
            ServiceResponse(service="/s", result=True, values={"success": True}, id=7),
            Status(level="error", msg="no", id=None)]


def test_no_op_class_reads_its_fields_per_op(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every op class has its field names read once, in order: to_obj needs no
    dataclasses.fields() call for any of them."""
    expected = [ops.to_obj(op) for op in _ops()]

    def refuse(_op: Any) -> Any:
        raise AssertionError("dataclasses.fields() called per op")

    monkeypatch.setattr(ops, "fields", refuse)
    assert [ops.to_obj(op) for op in _ops()] == expected
    assert all(cls in ops._FIELD_NAMES for cls in get_args(ops.Op))


def test_encode_makes_no_encoder_per_op(monkeypatch: pytest.MonkeyPatch) -> None:
    """encode gives json.dumps' text (compact, NaN as null, bytes as base64) without calling
    json.dumps, which makes an encoder a call."""
    expected = [ops.encode(op) for op in _ops()]
    assert expected[0] == '{"op":"publish","topic":"/a","msg":{"data":null,"raw":"AQI="}}'

    def refuse(*_args: Any, **_kwargs: Any) -> str:
        raise AssertionError("json.dumps called per op")

    monkeypatch.setattr(json, "dumps", refuse)
    assert [ops.encode(op) for op in _ops()] == expected
