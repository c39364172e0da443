"""One websocket client of the bridge: its frame loop, and the table its ops go through.

A :class:`Session` reads the client's frames, decodes them into ops
(:mod:`rosbridge_core.protocol`: the same sans-I/O core the client uses), asks
the gate (:mod:`rosbridge_core.security`: authentication, rate, names,
permissions) and hands each op to the capability that carries it out:

- :class:`~rosbridge_core.session.topics.SessionTopics`: advertise, unadvertise,
  publish, subscribe, unsubscribe;
- :class:`~rosbridge_core.session.services.SessionServices`: call_service and
  serving services;
- :class:`~rosbridge_core.session.actions.SessionActions`: goals and serving actions;
- the session itself: set_level.

Each capability lists its ops and methods in ``OPS``; the session builds one
table of bound methods from them, so an op costs one dictionary lookup. What a
client is sent goes through its :class:`~rosbridge_core.session.outbox.Outbox` (the
queues, the drop policy and the writer task).

Adding a capability
-------------------
Write a class in a module of its own with ``OPS`` (op class -> method name),
``LIMITS`` (op class -> method saying why the op would pass a per-connection limit),
``__init__(session)``, ``async close()`` (the client left) and
``recheck(gate) -> int`` (the role changed: end what it no longer allows), and
add it to :meth:`Session.__init__`'s ``capabilities`` line. A capability may also list
``RAW_OPS`` (op name -> method): the method gets the op's decoded JSON object before any
op value is made, and returns ``False`` at once, having done nothing, for anything but the
usual shape, which then takes the generic path (that names what is wrong). Only for hot
ops that need no permission of their own and add nothing the connection's limits count
(``service_response``: a client's answer to a ROS caller). It talks to the
session through its public members: ``send_op``/``send_text``, ``status``,
``error``, ``spawn`` (a task cancelled with the session), ``outbox``, ``gate``,
``graph`` (the ROS side: :class:`~rosbridge_core.graph.Graph`), ``limits``, ``shared``
(what every session shares: :class:`~rosbridge_core.session.host.Shared`), ``config``,
``loop`` and ``closed``.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Callable, Coroutine
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

from rosbridge_core.interfaces import BridgeError
from rosbridge_core.protocol import ops
from rosbridge_core.protocol.errors import ProtocolError
from rosbridge_core.protocol.frames import Conversation, decode_frame
from rosbridge_core.protocol.ops import ACKS_HEADER, parse_op
from rosbridge_core.security.permissions import MAY
from rosbridge_core.session import rosapi
from rosbridge_core.session.actions import SessionActions
from rosbridge_core.session.calls import Calls
from rosbridge_core.session.client_status import ClientStatus, client_status
from rosbridge_core.session.config import SessionConfig
from rosbridge_core.session.liveness import watch_link
from rosbridge_core.session.outbox import DEFAULT_QUEUE_LENGTH, Outbox
from rosbridge_core.session.resume import ACK_INTERVAL
from rosbridge_core.session.services import SessionServices
from rosbridge_core.session.topics import SessionTopics

if TYPE_CHECKING:
    from rosbridge_core.graph import Graph
    from rosbridge_core.security.gate import Gate
    from rosbridge_core.security.options import SecurityConfig
    from rosbridge_core.session.host import Shared
    from rosbridge_core.session.link import ClientLink

__all__ = ["DEFAULT_QUEUE_LENGTH", "Capability", "Session", "SessionConfig"]

log = logging.getLogger("bridge_server.session")

_LEVELS = {"none": 0, "error": 1, "warning": 2, "info": 3}

ROSAPI_REQUESTS: dict[str, tuple[str, ...]] = {
    name: rosapi.FIELDS.get(name, ()) for name in (*rosapi.HANDLERS, *rosapi.ASYNC_HANDLERS)}
"""The session's own ``/rosapi/*`` services with their request fields in order: what its
gate governs by the names a call asks about (security/gate.py)."""

_ENDING: set[asyncio.Task[None]] = set()
"""Clean-ups of kept sessions that were not resumed in time."""


async def wait_ended() -> None:
    """Return once the clean-ups of expired kept sessions have run."""
    if _ENDING:
        await asyncio.gather(*list(_ENDING), return_exceptions=True)


class Capability(Protocol):
    """A group of ops a session carries out (see "Adding a capability" above)."""

    OPS: ClassVar[dict[type[ops.Op], str]]
    LIMITS: ClassVar[dict[type[ops.Op], str]]
    """Op class -> method ``(op) -> str | None``: why the op would take the connection past
    one of its limits (``None``: it would not). Asked after the gate let the op through."""

    async def close(self) -> None:
        """The client left: release what it owned."""
        ...

    def recheck(self, gate: Gate) -> int:
        """The role changed: end what it no longer allows; how many ended."""
        ...


class Session:
    """One websocket client of the bridge."""

    protocol_name = "rosbridge"
    """The protocol the client speaks (the status page and /metrics show it)."""

    def __init__(self, shared: Shared, link: ClientLink, sid: int) -> None:
        """Client ``sid``'s session over ``link``, sharing ``shared`` with the other
        sessions of its server (the bridge, or a test's)."""
        self.shared = shared  # what the op groups share with the other sessions
        self.graph: Graph = shared.graph
        self.link = link
        self.sid = sid
        self.config: SessionConfig = shared.session_config
        self.loop = asyncio.get_running_loop()
        self.protocol = self._reassembly()
        self.calls = Calls(self.loop)
        self.level = _LEVELS["warning"]
        self.acks = link.header(ACKS_HEADER) == "1"
        self.errors_sent = 0
        self.outbox = Outbox(
            link, sid, self.config.control_limit, shared.security.config.max_queued_messages,
            self.config.drop_report_interval, lambda text: self.status("warning", text),
        )
        self.peer = link.address  # the client's address, and since when (for the status page)
        self.connected_at = time.time()
        self.frame_len = 0  # the size of the frame being handled (for /metrics)
        self.token: str | None = None  # a session that outlives its connection (resume.py)
        self.received = 0  # frames received in this session (told to a resuming client)
        self.resume_from = 0  # frames the resuming client had received (its handshake said)
        self._acked_received = 0
        self._ack_timer: asyncio.TimerHandle | None = None
        # auth, rate, names, permissions (security/gate.py)
        self.gate = shared.security.gate(self, ROSAPI_REQUESTS)
        self.topics = SessionTopics(self)
        self.services = SessionServices(self)
        self.actions = SessionActions(self)
        self.capabilities: tuple[Capability, ...] = (self.topics, self.services, self.actions)
        self._handlers: dict[type[ops.Op], Callable[[Any], None]] = {
            ops.SetLevel: self.set_level, ops.SessionAck: self._on_session_ack,
        }
        self._limits: dict[type[ops.Op], Callable[[Any], str | None]] = {}
        self._raw_ops: dict[str, Callable[[dict[str, Any]], bool]] = {}
        for capability in self.capabilities:
            for op_cls, method in capability.OPS.items():
                self._handlers[op_cls] = getattr(capability, method)
            for op_cls, method in capability.LIMITS.items():
                self._limits[op_cls] = getattr(capability, method)
            for name, method in getattr(capability, "RAW_OPS", {}).items():
                self._raw_ops[name] = getattr(capability, method)

    def _reassembly(self) -> Conversation:
        """The ``fragment`` op reassembly of the current link: held to the same bound as a
        single frame, and charged to the link's principal and address (security/accounts.py)."""
        holder = getattr(self.link, "holder", None)
        return Conversation(max_partial=16,
                             max_fragment_bytes=self.shared.link_config.max_message_size,
                             budget=None if holder is None else holder.fragments())

    @property
    def limits(self) -> SecurityConfig:
        """The bridge's per-connection limits (as configured now: SIGHUP may change them)."""
        return self.shared.security.config

    def refuse(self, op: Any, why: str) -> None:
        """Refuse ``op``: a status error, plus the failure shape a stock client waits for.

        A question about the client's own role (``/rosapi/may_*``, which an MCP server asks
        to know its tools) answered "no" is logged at DEBUG: it refused nothing the client
        meant to do, and read as a refusal in the operator's log."""
        own_role = isinstance(op, ops.CallService) and op.service in MAY
        self.error(f"{op.OP}: {why}", getattr(op, "id", None),
                   level=logging.DEBUG if own_role else logging.INFO)
        answer = op.refusal(why)
        if answer is not None:
            self.send_op(answer)

    # -- running -------------------------------------------------------------------------------

    @property
    def closed(self) -> bool:
        """Whether the connection has ended (nothing more is handled or sent)."""
        return self.outbox.closed

    async def run(self) -> None:
        """Serve the client until it disconnects; then release what it owned, unless the
        session is kept for the client to resume (resume.py)."""
        await self._serve()
        store = self.shared.resumable
        if self.token is not None:
            if not self.link.closed_by_client and store.park(self.token, self):
                log.info("client %d: its link is gone; its session is kept for %g s",
                         self.sid, store.config.session_keep)
                return
            store.forget(self.token, self)
        self.outbox.close()
        await self.cleanup()

    async def _serve(self) -> None:
        """Read and carry out the frames of the current connection until it closes."""
        writer = asyncio.create_task(self.outbox.writer(), name=f"session-{self.sid}-writer")
        link = self.link
        watcher = watch_link(link, self.sid, self.shared.link_config)
        # Each whole message with nothing queued before it is handled as it is read (no
        # turn of the loop to wake this task); the others come through the loop below.
        link.hand_frames_to(self.handle_frame)
        try:
            async for frame in link:
                self.handle_frame(frame)
        except link.closed_errors:
            pass
        finally:
            link.hand_frames_to(None)
            if watcher is not None:
                watcher.cancel()
            writer.cancel()
            with contextlib.suppress(asyncio.CancelledError, *link.closed_errors):
                await writer

    async def resume(self, link: ClientLink, client_received: int) -> None:
        """Carry on over a new connection: first what the client missed, then as before."""
        self.link = link
        self.peer = link.address
        # Fragments of an op cut off with the old connection cannot be completed now.
        self.protocol.close()
        self.protocol = self._reassembly()
        missing = self.outbox.resume(link, client_received)
        log.info("client %d: session resumed (%d frames sent again)", self.sid,
                 len(self.outbox.control))
        if missing:
            self.status("warning", f"session resumed, but {missing} messages sent while the "
                        "link was down were no longer kept (over this bridge's resume limit)")
        await self.run()

    def end_parked(self) -> None:
        """The kept session was not resumed in time: release what it owned."""
        self.token = None
        self.outbox.close()
        task = self.loop.create_task(self.cleanup())
        _ENDING.add(task)
        task.add_done_callback(_ENDING.discard)
        self.shared.session_ended(self)

    @property
    def parked(self) -> bool:
        """Whether the session is kept without a connection, waiting for its client."""
        return self.token is not None and self.token in self.shared.resumable.parked

    def describe(self, worker: int) -> ClientStatus:
        """This client's typed status (its entry in ``/status.json``) in worker ``worker``."""
        return client_status(
            sid=self.sid, worker=worker, protocol=self.protocol_name, address=self.peer,
            connected_at=self.connected_at, subs=self.topics.subs.values(), outbox=self.outbox,
            publishes=self.topics.publishers, serves=self.services.served,
            calls_in_flight=len(self.calls), parked=self.parked)

    def _count_received(self) -> None:
        self.received += 1
        if self._ack_timer is None:
            self._ack_timer = self.loop.call_later(ACK_INTERVAL, self._send_ack)

    def _on_session_ack(self, op: ops.SessionAck) -> None:
        if self.token is not None:
            self.received -= 1  # session_ack frames are not counted (handle_frame did)
        self.outbox.acked(op.count)

    def _send_ack(self) -> None:
        """Confirm the frames received (ahead of the queue; neither counted nor kept)."""
        self._ack_timer = None
        if self.received != self._acked_received and not self.outbox.closed:
            self._acked_received = self.received
            self.outbox.send_ack(ops.encode(ops.SessionAck(self.received)))

    async def cleanup(self) -> None:
        """Release what this client owned: each capability's, then the calls in flight."""
        if self._ack_timer is not None:
            self._ack_timer.cancel()
        self.protocol.close()  # the pieces of incomplete fragmented ops
        self.gate.end()
        for capability in self.capabilities:
            await capability.close()
        await self.calls.cancel_all()

    def spawn(self, coro: Coroutine[Any, Any, None]) -> None:
        """Run ``coro`` as a task of this client's, cancelled when it leaves."""
        self.calls.spawn(coro)

    # -- sending -------------------------------------------------------------------------------

    def send_text(self, text: str | bytes) -> None:
        """Queue one control frame (replies and status) for the writer."""
        self.outbox.send_text(text)

    def send_op(self, op: ops.Op) -> None:
        """Queue one op as JSON text."""
        self.outbox.send_text(ops.encode(op))

    def status(self, level: str, msg: str, id: ops.Id | None = None, *,
               always: bool = False) -> None:
        """Send a ``status`` op if the client's level admits it (``always``: whatever level
        it set; for what every client must hear, as a relay's robot going and coming back)."""
        if not always and _LEVELS.get(level, 1) > self.level:
            return
        self.send_op(ops.Status(level=level, msg=msg, id=id))

    def error(self, msg: str, id: ops.Id | None = None, kind: str = "request",
              level: int = logging.INFO) -> None:
        """Report a failed request to the client (``status`` level error); count it by kind.
        The bridge's log has it at ``level``."""
        log.log(level, "session %d: %s", self.sid, msg)
        self.errors_sent += 1
        self.shared.metrics.error(kind)
        self.status("error", msg, id)

    # -- receiving -----------------------------------------------------------------------------

    def handle_frame(self, frame: str | bytes) -> None:
        """Decode one frame and carry out the op it completes; errors go back as ``status``."""
        self.frame_len = size = len(frame)
        if self.token is not None:  # confirm it soon (the client keeps it until then)
            self._count_received()
        gate = self.gate
        if not gate.admit_frame(size):
            return
        try:
            obj = decode_frame(frame)
            if gate.authenticated:
                # a hot op in its usual shape is carried out as decoded (see RAW_OPS above)
                if type(obj) is dict and isinstance(name := obj.get("op"), str):
                    raw = self._raw_ops.get(name)
                    if raw is not None and self._carry_out(raw, obj, name, obj.get("id")):
                        return
                op = self.protocol.receive_decoded(obj)
            else:
                # Before authentication a frame is one op: fragments are not held for
                # reassembly (the gate refuses a fragment like any op but auth).
                op = parse_op(obj)
        except ProtocolError as exc:
            if not gate.authenticated:  # one answer, not one per frame of a flood
                gate.close(f"authentication required: the first op must be auth "
                           f"({exc.message[:60]})")
                return
            self.error(exc.message, exc.id, "protocol")
            return
        except Exception as exc:  # the core promises ProtocolError; stay up regardless
            log.exception("session %d: decoding a frame failed", self.sid)
            self.error(f"cannot decode the frame: {type(exc).__name__}", kind="internal")
            return
        if self.protocol.evicted:
            self._report_evicted()
        if op is not None:
            self.handle_op(op)

    def handle_op(self, op: ops.Op) -> None:
        """Carry out one parsed op."""
        if not self.gate.check(op):
            return
        limit = self._limits.get(type(op))
        if limit is not None and (why := limit(op)) is not None:
            self.refuse(op, why)
            return
        errors = self.errors_sent
        handler = self._handlers.get(type(op))
        if handler is None:
            self.error(f"{op.OP}: a client may not send this op", getattr(op, "id", None))
        else:
            self._carry_out(handler, op, op.OP, getattr(op, "id", None))
        if self.acks and op.ACKED and self.errors_sent == errors:
            # The client asked for verdicts (ACKS_HEADER): no error means accepted.
            self.send_op(ops.Status(level="info", msg=f"ok: {op.OP} {op.target()}",
                                    id=getattr(op, "id", None)))

    def _carry_out(self, handler: Callable[[Any], Any], arg: Any, name: str,
                   op_id: Any) -> bool:
        """``handler(arg)`` for the op ``name``; what it raises goes back to the client as an
        error (an internal one logged). False only when a raw handler did not take the op."""
        if type(op_id) is not str and (not isinstance(op_id, str | int)
                                       or isinstance(op_id, bool)):
            op_id = None  # the id as parse_op reads it (a str, the usual, checked first)
        try:
            return handler(arg) is not False
        except BridgeError as exc:
            self.error(f"{name}: {exc}", op_id)
        except UnicodeError:  # a JSON string with a lone surrogate ("\ud800") reached rclpy
            self.error(
                f"{name}: a string in the op is not valid Unicode text (a lone surrogate "
                "such as \\ud800?); ROS strings must be UTF-8",
                op_id,
            )
        except Exception:
            log.exception("session %d: %s failed", self.sid, name)
            self.error(f"{name}: internal error (the bridge log has the details)", op_id,
                       "internal")
        return True

    def _report_evicted(self) -> None:
        """Tell the sender which incomplete fragmented ops were dropped to make room."""
        limit = self.protocol.max_partial
        for frag_id, have, total in self.protocol.evicted:
            self.error(
                f"fragment {frag_id!r}: dropped with {have} of {total} pieces: more than "
                f"{limit} fragmented ops were incomplete at once on this connection",
                frag_id,
            )
        self.protocol.evicted.clear()

    # -- grants --------------------------------------------------------------------------------

    def recheck_grants(self) -> int:
        """The role changed (SIGHUP): end at once what it no longer allows; how many ended.

        Subscriptions, publishers, served services and served actions are checked against
        the gate as a new op for them would be; the client hears of each one that ends.
        """
        return sum(capability.recheck(self.gate) for capability in self.capabilities)

    # -- misc ----------------------------------------------------------------------------------

    def set_level(self, op: ops.SetLevel) -> None:
        """Set the least status level this client hears."""
        level = op.level.lower()
        if level not in _LEVELS:
            self.error(
                f"set_level: level must be one of none, error, warning, info, got {op.level!r}",
                op.id,
            )
            return
        self.level = _LEVELS[level]
