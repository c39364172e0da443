"""The bridge's part, played in memory: what :class:`~roslibpy_lite.mock.MockRos` runs on.

:class:`MemoryTransport` takes the client's ops as our bridge would and answers
with the bridge's ops, synchronously: an accepted advertise, subscribe or
advertise_service is confirmed with a ``status`` ``info`` naming its id, a
refused one gets the bridge's ``status`` error (a topic used with another
type); a publish reaches the subscriptions of its topic; a service call
reaches the served handler as a ``call_service`` and its ``service_response``
goes back to the caller; a call to a service nobody serves fails at once with
the bridge's "does not exist" text. The ``/rosapi/*`` introspection services are
answered from what it holds (:mod:`.memory_rosapi`). Actions go through the bridge's action
part, played by :mod:`.memory_actions`. With ``validate`` on, messages, requests
and responses are checked against the ``msgs`` class of their type, as the
bridge checks them against the ROS type.

Every op is copied through its JSON form (:func:`~roslibpy_lite.protocol.ops.encode`),
so subscribers never share objects with publishers, and what JSON cannot carry
fails as it does on a socket.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from ..exceptions import InvalidMessageError, UsageError
from ..messages import canonical_type, from_wire, lookup_message_class
from ..protocol import ops
from .memory_actions import ACTION_OPS, MemoryActions
from .memory_rosapi import MemoryRosapi, RosapiRefusal

if TYPE_CHECKING:
    from .base import Link

__all__ = ["MemoryTransport"]


@dataclass
class _Topic:
    type_name: str
    latched: Mapping[str, Any] | None = None
    history: list[Mapping[str, Any]] = field(default_factory=list)
    sub_ids: dict[ops.Id | None, None] = field(default_factory=dict)
    latch: bool = False
    advertised: bool = False


@dataclass
class _Forwarded:
    caller_id: ops.Id | None
    service: str
    type_name: str


class MemoryTransport:
    """A :class:`~roslibpy_lite.transports.base.Transport` that is its own bridge (module doc)."""

    url = "memory://mock"
    acks = True

    def __init__(self, *, validate: bool = True) -> None:
        self.validate = validate
        self.topics: dict[str, _Topic] = {}
        self.services: dict[str, str] = {}
        self._forwarded: dict[str, _Forwarded] = {}
        self._request_ids = 0
        self.actions = MemoryActions(self)
        """Served actions and goals in flight (:mod:`.memory_actions`)."""
        self.rosapi = MemoryRosapi(self)
        """The ``/rosapi/*`` answers and the parameter store (:mod:`.memory_rosapi`)."""
        self._up = False
        self._link: Link | None = None

    def bind(self, link: Link) -> None:
        """Attach the client."""
        self._link = link

    @property
    def connected(self) -> bool:
        """True between :meth:`open` and :meth:`drop`."""
        return self._up

    async def start(self) -> None:
        """Open (at once)."""
        self.open()

    def open(self) -> None:
        """Play a (re)connect: the client restores its handles on this fresh session."""
        assert self._link is not None
        self._up = True
        self._link.link_up()

    def drop(self) -> None:
        """Play a dropped connection: the session's publishers, subscriptions and services go."""
        assert self._link is not None
        self._up = False
        for entry in self.topics.values():
            entry.sub_ids.clear()
            entry.advertised = False
        self.services.clear()
        self._forwarded.clear()
        self.actions.drop()
        self._link.link_down()

    def encode(self, op: ops.Op) -> ops.Op:
        """A private copy of ``op`` through its JSON form."""
        return ops.parse_op(json.loads(ops.encode(op)))

    def write(self, frame: ops.Op) -> None:
        """Carry out one op as the bridge would; its answers reach the client at once."""
        handler = _HANDLERS.get(type(frame))
        if handler is None:
            self.send_error(f"{frame.OP}: not supported by MockRos", getattr(frame, "id", None))
            return
        handler(self, frame)

    @property
    def backlog(self) -> int:
        """Nothing ever waits."""
        return 0

    async def flush(self) -> None:
        """Nothing to flush."""

    async def close(self) -> None:
        """Stop."""
        self._up = False

    # -- the bridge's answers -------------------------------------------------------------------

    def to_client(self, op: ops.Op) -> None:
        assert self._link is not None
        if self._up:
            self._link.receive_op(op)

    def send_error(self, msg: str, id: ops.Id | None) -> None:
        self.to_client(ops.Status("error", msg, id=id))

    def _ok(self, op: ops.Advertise | ops.Subscribe | ops.AdvertiseService, name: str) -> None:
        self.to_client(ops.Status("info", f"ok: {op.OP} {name}", id=op.id))

    def check(self, wire: Mapping[str, Any], type_name: str, what: str) -> str | None:
        """The bridge's complaint about ``wire`` as a ``type_name``, or None."""
        cls = lookup_message_class(type_name) if self.validate else None
        if cls is None:
            return None
        try:
            from_wire(wire, cls, what)
        except InvalidMessageError as exc:
            return str(exc)
        return None

    # -- topics ---------------------------------------------------------------------------------

    def topic_of(self, topic: str, type_name: str, what: str) -> _Topic | str:
        """The topic's entry, or the bridge's complaint that it has another type."""
        entry = self.topics.get(topic)
        if entry is None:
            entry = self.topics[topic] = _Topic(type_name)
        elif entry.type_name != type_name:
            return f"{what}: topic {topic} already has type {entry.type_name}, not {type_name}"
        return entry

    def _advertise(self, op: ops.Advertise) -> None:
        entry = self.topic_of(op.topic, canonical_type(op.type, "msg"), "advertise")
        if isinstance(entry, str):
            self.send_error(entry, op.id)
            return
        entry.advertised = True
        entry.latch = bool(op.latch)
        self._ok(op, op.topic)

    def _unadvertise(self, op: ops.Unadvertise) -> None:
        entry = self.topics.get(op.topic)
        if entry is None or not entry.advertised:
            self.send_error(f"unadvertise: topic {op.topic} is not advertised by this client",
                            op.id)
            return
        entry.advertised = False

    def _publish(self, op: ops.Publish) -> None:
        entry = self.topics.get(op.topic)
        if entry is None:
            self.send_error(
                f"publish: topic {op.topic} is not advertised and the ROS graph has no type "
                "for it; send advertise first",
                op.id,
            )
            return
        problem = self.check(op.msg, entry.type_name, "msg")
        if problem is not None:
            self.send_error(f"publish to {op.topic} ({entry.type_name}): {problem}", op.id)
            return
        entry.history.append(op.msg)
        self._deliver(op.topic, entry, op.msg, latch=entry.latch)

    def _deliver(self, topic: str, entry: _Topic, msg: Mapping[str, Any], *, latch: bool) -> None:
        if latch:
            entry.latched = msg
        if entry.sub_ids:
            self.to_client(ops.Publish(topic, msg))

    def inject(self, topic: str, type_name: str, msg: Mapping[str, Any], *, latch: bool) -> None:
        """Publish ``msg`` as another node would (not recorded in the history)."""
        entry = self.topic_of(topic, type_name, "inject")
        if isinstance(entry, str):
            raise UsageError(entry)
        copy = self.encode(ops.Publish(topic, msg))
        assert isinstance(copy, ops.Publish)
        self._deliver(topic, entry, copy.msg, latch=latch)

    def _subscribe(self, op: ops.Subscribe) -> None:
        type_name = canonical_type(op.type, "msg") if op.type else None
        entry = self.topics.get(op.topic)
        if entry is None:
            if type_name is None:
                self.send_error(f"subscribe: topic {op.topic} has no type yet; give one", op.id)
                return
            entry = self.topics[op.topic] = _Topic(type_name)
        elif type_name is not None and entry.type_name != type_name:
            self.send_error(
                f"subscribe: topic {op.topic} has type {entry.type_name} in the ROS graph, "
                f"not {type_name}",
                op.id,
            )
            return
        first = not entry.sub_ids
        entry.sub_ids[op.id] = None
        self._ok(op, op.topic)
        if first and entry.latched is not None:
            self.to_client(ops.Publish(op.topic, entry.latched))

    def _unsubscribe(self, op: ops.Unsubscribe) -> None:
        entry = self.topics.get(op.topic)
        if entry is not None:
            if op.id is None:
                entry.sub_ids.clear()
            else:
                entry.sub_ids.pop(op.id, None)

    # -- services -------------------------------------------------------------------------------

    def _advertise_service(self, op: ops.AdvertiseService) -> None:
        self.services[op.service] = canonical_type(op.type, "srv")
        self._ok(op, op.service)

    def _unadvertise_service(self, op: ops.UnadvertiseService) -> None:
        self.services.pop(op.service, None)
        for rid, fwd in list(self._forwarded.items()):
            if fwd.service == op.service:
                del self._forwarded[rid]
                self._answer(fwd, False, f"service {op.service} is no longer served")

    def _call_service(self, op: ops.CallService) -> None:
        if op.service.startswith("/rosapi/") and op.service not in self.services:
            self._call_rosapi(op)
            return
        served = self.services.get(op.service)
        type_name = canonical_type(op.type, "srv") if op.type else served
        fwd = _Forwarded(op.id, op.service, type_name or "")
        if served is None:
            self._answer(fwd, False,
                         f"service {op.service} does not exist (not in the ROS graph)")
            return
        if type_name != served:
            self._answer(fwd, False, f"service {op.service} has type {served}, not {type_name}")
            return
        args = op.args if isinstance(op.args, Mapping) else {}
        problem = self.check(args, f"{served}_Request", "args")
        if problem is not None:
            self._answer(fwd, False, f"{op.service}: bad request: {problem}")
            return
        request_cls = lookup_message_class(f"{served}_Request")
        if request_cls is not None:  # the fields left out get their defaults, as in ROS
            args = request_cls.from_json(args).to_json()
        self._request_ids += 1
        rid = f"service_request:{op.service}:{self._request_ids}"
        self._forwarded[rid] = fwd
        self.to_client(ops.CallService(op.service, args, served, id=rid))

    def _call_rosapi(self, op: ops.CallService) -> None:
        fwd = _Forwarded(op.id, op.service, "")
        try:
            values = self.rosapi.answer(op.service, op.args if isinstance(op.args, Mapping) else {})
        except RosapiRefusal as exc:
            self._answer(fwd, False, f"{op.service}: {exc}")  # as the bridge words it
            return
        if values is None:
            self._answer(fwd, False, f"service {op.service} does not exist (MockRos answers "
                         f"{', '.join(sorted(self.rosapi.types()))})")
            return
        self._answer(fwd, True, values)

    def _service_response(self, op: ops.ServiceResponse) -> None:
        fwd = self._forwarded.pop(str(op.id), None)
        if fwd is None:
            return
        if not op.result:
            reason = op.values if isinstance(op.values, str) else "the serving client failed"
            self._answer(fwd, False, f"service {fwd.service} failed: {reason}")
            return
        values = op.values if isinstance(op.values, Mapping) else {}
        problem = self.check(values, f"{fwd.type_name}_Response", "values")
        if problem is not None:
            self._answer(fwd, False,
                         f"service {fwd.service} answered with a bad response: {problem}")
            return
        self._answer(fwd, True, values)

    def _answer(self, fwd: _Forwarded, result: bool, values: Mapping[str, Any] | str) -> None:
        self.to_client(ops.ServiceResponse(fwd.service, result, values, id=fwd.caller_id))

    def _set_level(self, op: ops.SetLevel) -> None:
        pass

    def _action(self, op: ops.Op) -> None:
        self.actions.handle(op)


_HANDLERS: dict[type[Any], Any] = {
    ops.Advertise: MemoryTransport._advertise,
    ops.Unadvertise: MemoryTransport._unadvertise,
    ops.Publish: MemoryTransport._publish,
    ops.Subscribe: MemoryTransport._subscribe,
    ops.Unsubscribe: MemoryTransport._unsubscribe,
    ops.AdvertiseService: MemoryTransport._advertise_service,
    ops.UnadvertiseService: MemoryTransport._unadvertise_service,
    ops.CallService: MemoryTransport._call_service,
    ops.ServiceResponse: MemoryTransport._service_response,
    ops.SetLevel: MemoryTransport._set_level,
    **{op: MemoryTransport._action for op in ACTION_OPS},
}
