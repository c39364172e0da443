"""Topics: advertise and publish, subscribe and receive.

Publishers of one topic made by several ``advertise`` calls share one
``advertise`` request (the first handle's id; the next handle takes it over
when the first closes). While disconnected, ``publish`` keeps up to
``offline_buffer`` messages per publisher (the oldest dropped), written after
the next connect; every handle's request is sent again first.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable, Coroutine, Mapping
from typing import TYPE_CHECKING, Any

from msgs.cdr import CdrError, decoder_for, encode
from msgs.runtime import ValidationError
from rosbridge_core.protocol import ops

from .._api_types import ConnectionState
from ..exceptions import (
    ConnectionClosed,
    Disconnected,
    DuplicateCallbackWarning,
    NotConnected,
    ReplacedSubscriptionWarning,
    RosLibError,
    ServiceError,
    UsageError,
)
from ..handles import Publisher, Subscription
from ..jupyter import Cell, current_cell
from ..messages import (
    RawMessage,
    bytes_fixer,
    check_name,
    lookup_message_class,
    message_type,
    name_hint,
    warn_user,
)
from . import TopicsHost, Tracked

log = logging.getLogger("roslibpy_lite.client")

if TYPE_CHECKING:
    from msgs.runtime import Message

    from .._api_types import MessageCallback
    from .introspection import Introspection

__all__ = ["GRAPH_HINT_TIMEOUT", "Topics"]

GRAPH_HINT_TIMEOUT = 2.0
"""Seconds an empty wait spends asking the graph whether its topic is misspelt."""


class Topics:
    """One client's publishers and subscriptions (see the module docstring)."""

    def __init__(self, host: TopicsHost, *, offline_buffer: int, max_pending: int) -> None:
        self.host = host
        self.offline_buffer = offline_buffer
        self.max_pending = max_pending
        # Handles, in creation order (dicts keep it) for restoring after a reconnect.
        self.publishers: dict[str, list[Publisher[Any]]] = {}
        self.subscriptions: dict[str, Subscription[Any]] = {}  # by request id
        self.graph: Introspection | None = None
        """Asked why a wait ended empty (set by the client)."""
        # A notebook cell's latest open subscription of a topic, and the run that made it.
        self._by_cell: dict[tuple[str, str], tuple[Subscription[Any], str]] = {}
        self.by_topic: dict[str, tuple[Subscription[Any], ...]] = {}
        self._decoders: dict[str, Callable[[bytes], dict[str, Any]]] = {}
        host.route(ops.Publish, self._deliver)
        host.on_restore(self._restore)
        host.on_drop(self._drop)
        host.on_stray_error(self._publish_failed)

    # -- publishers ----------------------------------------------------------------------------

    def advertise(
        self, topic: str, type: str | type[Message], latch: bool, queue_size: int,
        strict: bool | None = None,
    ) -> Publisher[Any]:
        """A new publisher handle (see ``RosBase.advertise``)."""
        host = self.host
        host.check_open()
        check_name(topic, "topic")
        type_name, cls = message_type(type)
        pubs = self.publishers.get(topic)
        if pubs and pubs[0].type_name != type_name:
            raise UsageError(
                f"advertise {topic}: already advertised here as {pubs[0].type_name}, "
                f"not {type_name}"
            )
        pub: Publisher[Any] = Publisher(
            self, topic, type_name, cls, latch=latch, queue_size=queue_size,
            id=host.new_id("advertise", topic), offline_buffer=self.offline_buffer,
            check_cls=self.check_class(type_name, cls), strict=strict,
            completeness=host.completeness,
        )
        if pubs:
            pubs.append(pub)
        else:
            self.publishers[topic] = [pub]
            host.request(Tracked(topic, handle=pub, refuse=self._refuse_publishers(topic, pub),
                                 forget=self._forget_publishers(topic)), pub.request_op())
        return pub

    def _refuse_publishers(
        self, topic: str, pub: Publisher[Any]
    ) -> Callable[[RosLibError], None]:
        def refuse(error: RosLibError) -> None:  # every handle sharing the advertise fails
            for each in self.publishers.get(topic, [pub]):
                each.fail(error)
        return refuse

    def _forget_publishers(self, topic: str) -> Callable[[], None]:
        def forget() -> None:
            for pub in self.publishers.pop(topic, []):
                self.host.untrack(pub.id)
        return forget

    def check_class(self, type_name: str, cls: type[Message] | None) -> type[Message] | None:
        """The class dicts of ``type_name`` are checked against (None: unchecked)."""
        if cls is not None:
            return cls
        return lookup_message_class(type_name) if self.host.validate else None

    def publish_message(
        self, pub: Publisher[Any], wire: Mapping[str, Any]
    ) -> Coroutine[Any, Any, None] | None:
        t = self.host.transport
        if t.connected:
            t.write(t.encode(ops.Publish(pub.topic, wire)))
            if t.backlog > self.max_pending:
                return t.flush()
            return None
        if self.offline_buffer == 0:  # no buffering: fail fast, naming the state
            self.host.require_link(f"publish to {pub.topic}",
                                   "offline_buffer > 0 keeps messages until it is back")
            raise Disconnected(f"publish to {pub.topic}: the connection to {t.url} is down")
        self.host.check_open()
        frame = t.encode(ops.Publish(pub.topic, wire))  # a copy, checked now
        if len(pub.offline_queue) >= self.offline_buffer:
            pub.offline_queue.popleft()
            pub.dropped += 1
        pub.offline_queue.append(frame)
        return None

    def forget_publisher(self, pub: Publisher[Any]) -> None:
        pubs = self.publishers.get(pub.topic)
        if not pubs or pub not in pubs:
            return
        first = pubs[0]
        pubs.remove(pub)
        host = self.host
        if pubs:
            if first is pub:  # the request id lives on with the next handle
                record = host.untrack(pub.id)
                if record is not None:
                    record.handle = pubs[0]
                    host.track(pubs[0].id, record)
            return
        del self.publishers[pub.topic]
        host.untrack(pub.id)
        if host.state is not ConnectionState.CLOSED:
            host.send(ops.Unadvertise(pub.topic, id=first.id))

    def _publish_failed(self, text: str, error: RosLibError) -> None:
        """A bridge's ``publish to <topic> ...`` error: the topic's publishers raise it once."""
        if not text.startswith("publish to "):
            return
        topic = text[len("publish to "):].split(" ", 1)[0].rstrip(":")
        found = self.publishers.get(topic) or self.publishers.get(topic.lstrip("/"))
        for pub in found or []:
            pub.fail_next_publish(error)

    # -- subscriptions -------------------------------------------------------------------------

    def subscribe(
        self,
        topic: str,
        type: str | type[Message],
        callback: MessageCallback | None,
        *,
        throttle_rate: int,
        queue_length: int,
        compression: str,
        fragment_size: int | None,
        buffer_size: int,
        raw: bool = False,
    ) -> Subscription[Any]:
        """A new subscription handle (see ``RosBase.subscribe``)."""
        host = self.host
        host.check_open()
        check_name(topic, "topic")
        type_name, cls = message_type(type)
        if raw:
            if compression not in ("none", "cbor-raw"):
                raise UsageError(f"subscribe {topic}: raw=True takes the bridge's "
                                 f"'cbor-raw' form, not compression={compression!r}")
            compression, cls = "cbor-raw", None
        if compression in ("cbor", "cbor-raw"):
            _need_cbor(compression)
        if compression == "cbor-raw" and not raw and self._cdr_decoder(type_name) is None:
            raise UsageError(
                f"subscribe {topic}: compression='cbor-raw' needs the definition of "
                f"{type_name} on this machine to decode CDR, and msgs has none; load it "
                "with await ros.load_types(...) or use 'cbor'"
            )
        sub: Subscription[Any] = Subscription(
            self, topic, type_name, cls, throttle_rate=throttle_rate, queue_length=queue_length,
            compression=compression, fragment_size=fragment_size, buffer_size=buffer_size,
            id=host.new_id("subscribe", topic), raw=raw,
        )
        cell = current_cell()
        if cell is not None:
            self._replace_from_cell(cell, sub)
        if callback is not None:
            sub.on_message(callback)
            self._move_callback(topic, callback)
        self.subscriptions[sub.id] = sub
        self.by_topic[topic] = (*self.by_topic.get(topic, ()), sub)
        host.request(Tracked(topic, handle=sub, forget=lambda: self._forget_sub(sub)),
                     sub.request_op())
        return sub

    def _replace_from_cell(self, cell: Cell, sub: Subscription[Any]) -> None:
        """A notebook cell run again subscribes to a topic it subscribed to in an earlier
        run: that subscription closes (ReplacedSubscriptionWarning), so a re-run keeps one.
        Several subscriptions made by one run of a cell are all kept."""
        key = (cell.key, sub.topic)
        earlier = self._by_cell.get(key)
        self._by_cell[key] = (sub, cell.run)
        if earlier is None or earlier[1] == cell.run or earlier[0].closed:
            return
        old = earlier[0]
        self._close_quietly(old)
        run = f" (In [{cell.number}])" if cell.number is not None else ""
        warn_user(ReplacedSubscriptionWarning(
            f"subscribe {sub.topic}: this cell{run} subscribed to {sub.topic} when it ran "
            f"before; that subscription was closed ({old.received} received, {old.pending} "
            "buffered), so a re-run keeps one; ros.subscriptions() lists what is open"))

    def _close_quietly(self, sub: Subscription[Any]) -> None:
        """Close ``sub`` from inside a (non-async) subscribe call."""
        self.forget_subscription(sub)
        sub.mark_closed()
        if sub.consumer is not None:
            sub.consumer.cancel()

    async def silence_note(self, topic: str) -> str:
        """Why nothing may have come on ``topic``, for an error text: ``"; nothing publishes
        /Imu; did you mean '/imu'?"`` when no node publishes it; ``""`` when one does, or the
        graph cannot be asked (the link down, no answer within GRAPH_HINT_TIMEOUT; a bridge
        without rosapi is not asked again)."""
        graph = self.graph
        if graph is None or self.host.state is not ConnectionState.CONNECTED:
            return ""
        try:
            async with asyncio.timeout(GRAPH_HINT_TIMEOUT):
                found = await graph.rosapi("publishers", {"topic": topic},
                                           timeout=GRAPH_HINT_TIMEOUT)
                if found.get("publishers"):
                    return ""
                names = [t.name for t in await graph.topics(timeout=GRAPH_HINT_TIMEOUT)]
        except ServiceError:
            self.graph = None  # a bridge without rosapi (or this call): not asked again
            return ""
        except (RosLibError, TimeoutError):
            return ""
        return f"; nothing publishes {topic} in the graph; {name_hint(topic, names)}"

    def _move_callback(self, topic: str, callback: MessageCallback) -> None:
        """An open subscription of ``topic`` that already calls ``callback`` (or the same
        code: a re-run notebook cell) gives it up, so it runs once; one left with no
        callback closes. Says so with a DuplicateCallbackWarning."""
        for earlier in self.by_topic.get(topic, ()):
            found = earlier.remove_callback(callback, same_callback)
            if found is None:
                continue
            left = earlier.has_callbacks()
            if not left:
                self._close_quietly(earlier)
            name = getattr(callback, "__qualname__", repr(callback))
            warn_user(DuplicateCallbackWarning(
                f"subscribe {topic}: callback {name} already ran for an earlier subscription "
                f"of {topic}; it now runs once, for the new one (the earlier subscription "
                f"{'keeps its other callbacks' if left else 'is closed'})"))

    def _deliver(self, op: ops.Publish) -> None:
        subs = self.by_topic.get(op.topic)
        if subs is None:
            return
        msg = op.msg
        if len(msg) == 3 and type(msg.get("bytes")) is bytes and "nsecs" in msg:
            # compression cbor-raw: raw subscriptions take the bytes, others a decoded dict
            cooked = tuple(s for s in subs if not s.raw)
            decoded = self._from_cdr(cooked, msg["bytes"]) if cooked else None
            raw = None if len(cooked) == len(subs) else RawMessage(
                op.topic, subs[0].type_name, msg["bytes"],
                msg["secs"] * 1_000_000_000 + msg["nsecs"])
            for sub in subs:
                if sub.raw:
                    assert raw is not None
                    sub.deliver(raw)
                elif decoded is not None:
                    sub.deliver(decoded)
            return
        encoded: RawMessage | None = None
        fix = bytes_fixer(subs[0].type_name)  # uint8[] fields as bytes, whatever came
        fixed = None
        for sub in subs:
            if not sub.raw:
                if fix is None or sub.uint8_as_sent:
                    sub.deliver(msg)
                    continue
                if fixed is None:
                    fixed = fix(msg)
                sub.deliver(fixed)
                continue
            if encoded is None:  # a server without cbor-raw, or MockRos: serialize here
                encoded = self._to_cdr(sub, msg)
                if encoded is None:
                    continue
            sub.deliver(encoded)

    def _to_cdr(self, sub: Subscription[Any], msg: Mapping[str, Any]) -> RawMessage | None:
        """A message that came in its JSON/CBOR form as a RawMessage (None: it cannot be)."""
        cls = lookup_message_class(sub.type_name)
        try:
            if cls is None:
                raise UsageError(f"{sub.type_name} is not a type msgs knows")
            data = encode(cls.from_json(msg))
        except (UsageError, ValidationError, CdrError) as exc:
            sub.decode_errors += 1
            log.warning("a message on %s cannot be serialized for a raw subscription: %s",
                        sub.topic, exc)
            return None
        return RawMessage(sub.topic, sub.type_name, data, time.time_ns())

    def _cdr_decoder(self, type_name: str) -> Callable[[bytes], dict[str, Any]] | None:
        """The CDR decoder of ``type_name`` (None: msgs does not know the type)."""
        found = self._decoders.get(type_name)
        if found is None:
            cls = lookup_message_class(type_name)
            if cls is None:
                return None
            found = self._decoders[type_name] = decoder_for(cls)
        return found

    def _from_cdr(
        self, subs: tuple[Subscription[Any], ...], data: bytes
    ) -> dict[str, Any] | None:
        """A ``cbor-raw`` message in its wire form (None: it does not decode; counted)."""
        decode = self._cdr_decoder(subs[0].type_name)
        try:
            if decode is None:
                raise CdrError(subs[0].type_name, "", "msgs does not know this type")
            return decode(data)
        except CdrError as exc:
            for sub in subs:
                sub.decode_errors += 1
            log.warning("a cbor-raw message on %s does not decode: %s", subs[0].topic, exc)
            return None

    def _forget_sub(self, sub: Subscription[Any]) -> None:
        self._drop_sub(sub)

    def _drop_sub(self, sub: Subscription[Any]) -> bool:
        if self.subscriptions.pop(sub.id, None) is None:
            return False
        self.host.untrack(sub.id)
        if self._by_cell:
            for key, (made, _) in list(self._by_cell.items()):
                if made is sub:
                    del self._by_cell[key]
        left = tuple(s for s in self.by_topic.get(sub.topic, ()) if s is not sub)
        if left:
            self.by_topic[sub.topic] = left
        else:
            self.by_topic.pop(sub.topic, None)
        return True

    def forget_subscription(self, sub: Subscription[Any]) -> None:
        if self._drop_sub(sub) and self.host.state is not ConnectionState.CLOSED:
            self.host.send(ops.Unsubscribe(sub.topic, id=sub.id))

    def consumers(self) -> list[asyncio.Task[None]]:
        """The tasks running subscriptions' async callbacks (cancelled on close)."""
        return [t for s in self.subscriptions.values() if (t := s.consumer) is not None]

    # -- the handles' other hooks --------------------------------------------------------------

    async def settle(self, handle: Any) -> None:
        await self.host.settle(handle)

    def require_link(self, what: str, hint: str = "pass wait_connected=True to wait for it"
                     ) -> None:
        self.host.require_link(what, hint)

    def link_note(self) -> str:
        return self.host.link_note()

    # -- the connection ------------------------------------------------------------------------

    def _restore(self) -> None:
        """A connection is open: every publisher's and subscription's request again."""
        host = self.host
        for pubs in self.publishers.values():
            host.send(pubs[0].request_op())
        for sub in self.subscriptions.values():
            sub.error = None
            host.send(sub.request_op())

    def flush_offline(self) -> None:
        """Write the messages published while disconnected (after every request is restored)."""
        t = self.host.transport
        for pubs in self.publishers.values():
            for pub in pubs:
                pub.error = None
                while pub.offline_queue and t.connected:
                    t.write(pub.offline_queue.popleft())

    def _drop(self, error: ConnectionClosed) -> None:
        if self.host.state is not ConnectionState.CLOSED:
            # a reconnect follows: handles stay, publishers buffer; fresh reads fail now
            state = self.host.state.value
            lost = NotConnected(f"the connection to {self.host.transport.url} dropped (state "
                                f"{state}) while waiting for a message", state=state)
            for sub in self.subscriptions.values():
                sub.link_lost(lost)
            return
        for sub in list(self.subscriptions.values()):
            sub.mark_closed()
        for pubs in self.publishers.values():
            for pub in pubs:
                pub.offline_queue.clear()


def same_callback(a: Any, b: Any) -> bool:
    """Whether ``a`` and ``b`` are one callback: equal, or the same code with the same
    defaults, closure and bound object (a function defined again by a re-run cell)."""
    if a == b:
        return True
    fa, fb = getattr(a, "__func__", a), getattr(b, "__func__", b)
    if getattr(a, "__self__", None) is not getattr(b, "__self__", None):
        return False
    code_a, code_b = getattr(fa, "__code__", None), getattr(fb, "__code__", None)
    if code_a is None or code_a != code_b or fa.__qualname__ != fb.__qualname__:
        return False
    if fa.__defaults__ != fb.__defaults__ or fa.__kwdefaults__ != fb.__kwdefaults__:
        return False
    cells_a, cells_b = fa.__closure__ or (), fb.__closure__ or ()
    return all(x.cell_contents is y.cell_contents for x, y in zip(cells_a, cells_b, strict=True))


def _need_cbor(compression: str) -> None:
    try:
        import cbor2  # noqa: F401
    except ImportError:
        raise UsageError(
            f"compression={compression!r} needs cbor2: install roslibpy-lite[cbor]"
        ) from None
