"""Property: whatever frame arrives, the client's receive path neither raises nor stalls."""

from __future__ import annotations

import asyncio
import json
from typing import Any

import cbor2
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from roslibpy_lite import Client

_json = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=4),
    max_leaves=12,
)
_ops = st.fixed_dictionaries(
    {"op": st.sampled_from(["publish", "service_response", "call_service", "status", "fragment",
                            "advertise", "bogus"])},
    optional={"topic": st.sampled_from(["/f", "/g"]) | _json, "msg": _json, "id": _json,
              "service": _json, "values": _json, "result": _json, "level": _json,
              "data": _json, "num": _json, "total": _json, "args": _json},
)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(frames=st.lists(_ops | _json, min_size=1, max_size=6), binary=st.booleans(),
       raw=st.binary(max_size=40))
def test_any_frame_is_delivered_or_ignored(frames: list[Any], binary: bool, raw: bytes) -> None:
    """Random ops, random JSON and random bytes never make the receive path raise."""

    async def run() -> None:
        client = Client("ws://127.0.0.1:9")
        sub = client.subscribe("/f", "std_msgs/msg/Int32", buffer_size=1000)
        client.advertise_service("/s", "mult_msgs/srv/MultFloats", lambda req: {"result": 1.0})
        for frame in frames:
            client._receive(cbor2.dumps(frame) if binary else json.dumps(frame))
        client._receive(raw)
        client._receive(json.dumps({"op": "publish", "topic": "/f", "msg": {"data": 1}}))
        # The last, valid message still arrives after whatever came before.
        while True:
            msg = await sub.get(1)
            if msg == {"data": 1} and sub.pending == 0:
                break
        await client.close()

    asyncio.run(run())
