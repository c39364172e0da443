"""The host :class:`~roslibpy_lite.ros.RosBase` gives its capabilities (:class:`_Host`):
what they share (:class:`roslibpy_lite.capabilities.Host`: sending, routing received ops,
request ids, the requests the bridge may answer or refuse by id, the error hooks) and the
hooks the transport calls (:class:`roslibpy_lite.transports.base.Link`: link up and down,
shut down, an op received), with the bridge's status ops and the refusals they carry."""

from __future__ import annotations

import asyncio
import itertools
import logging
from collections.abc import Callable, Coroutine
from typing import TYPE_CHECKING, Any

from rosbridge_core.protocol import ops

from ._aio import running_loop
from ._api_types import ConnectionState, ErrorCallback
from .capabilities import Tracked
from .exceptions import (
    ConnectionClosed,
    Disconnected,
    NotConnected,
    ProtocolError,
    RosLibError,
    StatusError,
    status_error,
)
from .messages import Completeness
from .state import StateHub

if TYPE_CHECKING:
    from .transports.base import Transport

log = logging.getLogger("roslibpy_lite.client")


class _Host:
    """What the capabilities share (:class:`roslibpy_lite.capabilities.Host`), and the
    hooks the transport calls (:class:`roslibpy_lite.transports.base.Link`)."""

    def __init__(self, transport: Transport, validate: bool, verdict_timeout: float,
                 strict: bool = False) -> None:
        self.transport = transport
        self.validate = validate
        self.completeness = Completeness(strict)
        self.verdict_timeout = verdict_timeout
        self.hub = StateHub(ConnectionState.CONNECTING)
        self._ids = itertools.count(1)
        self._pending: dict[str, Tracked] = {}
        self._routes: dict[type[Any], Callable[[Any], None]] = {ops.Status: self._on_status}
        self._restorers: list[Callable[[], None]] = []
        self._drops: list[Callable[[ConnectionClosed], None]] = []
        self._stray: list[Callable[[str, RosLibError], None]] = []
        self.tasks: set[asyncio.Task[None]] = set()
        self.status_callbacks: list[Callable[[ops.Status], None]] = []
        self.error_callbacks: list[ErrorCallback] = []
        self.status_errors = 0

    # -- what capabilities use -----------------------------------------------------------------

    @property
    def state(self) -> ConnectionState:
        return self.hub.state

    def check_open(self) -> None:
        if self.hub.state is ConnectionState.CLOSED:
            raise ConnectionClosed(f"the connection to {self.transport.url} is closed")

    def require_link(self, what: str, hint: str = "pass wait_connected=True to wait for it"
                     ) -> None:
        state = self.hub.state
        if state is ConnectionState.CONNECTED:
            return
        self.check_open()
        raise NotConnected(
            f"{what}: the connection to {self.transport.url} is down (state {state.value}); "
            f"{hint}", state=state.value)

    def link_note(self) -> str:
        state = self.hub.state
        return "" if state is ConnectionState.CONNECTED else f" (state {state.value})"

    def route(self, op_type: type[Any], handler: Callable[[Any], None]) -> None:
        self._routes[op_type] = handler

    def on_restore(self, fn: Callable[[], None]) -> None:
        self._restorers.append(fn)

    def on_drop(self, fn: Callable[[ConnectionClosed], None]) -> None:
        self._drops.append(fn)

    def on_stray_error(self, fn: Callable[[str, RosLibError], None]) -> None:
        self._stray.append(fn)

    def send(self, op: ops.Op) -> None:
        t = self.transport
        if t.connected:
            t.write(t.encode(op))

    def send_or(self, op: ops.Op, fallback: Callable[[str], ops.Op]) -> None:
        t = self.transport
        if not t.connected:
            return
        try:
            frame = t.encode(op)
        except ProtocolError as exc:
            frame = t.encode(fallback(exc.message))
        t.write(frame)

    def new_id(self, kind: str, name: str) -> str:
        return f"{kind}:{name}:{next(self._ids)}"

    def request(self, pending: Tracked, op: ops.Op) -> None:
        self._pending[pending.handle.id] = pending
        t = self.transport
        if t.connected:
            if t.acks:
                pending.verdict = asyncio.Event()
            t.write(t.encode(op))

    def track(self, id: str, pending: Tracked) -> None:
        self._pending[id] = pending

    def untrack(self, id: str) -> Tracked | None:
        return self._pending.pop(id, None)

    async def settle(self, handle: Any) -> None:
        await self.transport.flush()
        key = handle.id
        record = self._pending.get(key)
        event = record.verdict if record is not None else None
        if record is not None and event is not None:
            record.awaited = True
            try:
                async with asyncio.timeout(self.verdict_timeout):
                    await event.wait()
            except TimeoutError:
                log.debug("no verdict on %s within %s s", key, self.verdict_timeout)
            finally:
                record.awaited = False
                record.verdict = None
        record = self._pending.get(key)
        if handle.error is not None and record is not None and record.handle is handle:
            if record.report is not None:
                record.report.cancel()
                record.report = None
            del self._pending[key]  # refused: forget the handle (nothing is sent)
            if record.forget is not None:
                record.forget()
            raise handle.error

    async def flush(self) -> None:
        await self.transport.flush()

    async def wait_connected(self, timeout: float | None = None) -> None:
        await self.hub.wait_connected(timeout)

    def spawn(self, coro: Coroutine[Any, Any, None]) -> asyncio.Task[None]:
        task: asyncio.Task[None] = asyncio.get_running_loop().create_task(coro)
        self.tasks.add(task)
        task.add_done_callback(self.tasks.discard)
        return task

    # -- the transport's hooks -----------------------------------------------------------------

    def link_up(self) -> None:
        """A connection is open: every handle's request again, then buffered messages."""
        for restore in self._restorers:
            restore()
        self.hub.set(ConnectionState.CONNECTED)

    def link_down(self) -> None:
        """The connection dropped; a reconnect follows. Calls in flight fail at once."""
        self.hub.set(ConnectionState.RECONNECTING)
        url = self.transport.url
        self._fail_calls(lambda service, call_id: Disconnected(
            f"connection to {url} dropped while calling {service} (request {call_id})"
        ))
        self._release_verdicts()
        for fn in self._drops:
            fn(Disconnected(f"connection to {url} dropped"))

    def shut_down(self, error: ConnectionClosed) -> None:
        """Enter CLOSED: fail calls, end subscriptions (no messages to the server)."""
        self.hub.set(ConnectionState.CLOSED)
        self._fail_calls(lambda service, call_id: error)
        self._release_verdicts()
        for fn in self._drops:
            fn(error)

    def _fail_calls(self, error: Callable[[str, str], Exception]) -> None:
        """Fail every call in flight (a record with a future) with ``error(name, id)``."""
        for key, record in list(self._pending.items()):
            future = record.future
            if future is not None:
                del self._pending[key]
                if not future.done():
                    future.set_exception(error(record.name, key))

    def _release_verdicts(self) -> None:
        for record in self._pending.values():
            event, record.verdict = record.verdict, None
            if event is not None:
                event.set()

    def receive_op(self, op: ops.Op) -> None:
        """Dispatch one op from the transport (never raises)."""
        route = self._routes.get(type(op))
        if route is None:
            log.debug("ignoring a %s op", op.OP)
            return
        try:
            route(op)
        except Exception:  # a bug here must not kill the connection
            log.exception("failed to handle a %s op", op.OP)

    # -- status ops ----------------------------------------------------------------------------

    def _on_status(self, op: ops.Status) -> None:
        for cb in list(self.status_callbacks):
            try:
                cb(op)
            except Exception:
                log.exception("status callback raised")
        key = str(op.id) if op.id is not None else None
        record = self._pending.get(key) if key is not None else None
        if op.level != "error":
            if record is not None and record.handle is not None:
                if op.level == "info" and record.confirm is not None:
                    record.confirm()
                    return
                event, record.verdict = record.verdict, None
                if event is not None and op.level == "info":
                    event.set()  # the bridge accepted the request
                    return
                if op.level == "info":
                    return  # an acknowledgement after a reconnect
            # a warning the bridge sends of itself (a relay's robot went away) is one
            log.log(logging.WARNING if op.level == "warning" else logging.INFO,
                    "bridge status %s: %s", op.level, op.msg)
            return
        error = status_error(op.msg, level=op.level, id=op.id)  # Forbidden when it says so
        if key is not None and record is not None:
            future = record.future
            if future is not None:
                del self._pending[key]
                if not future.done():
                    future.set_exception(error)
                return
            if record.handle is not None:
                self._refused(key, record, error)
                return
        for fn in self._stray:
            fn(op.msg, error)
        self.status_errors += 1
        self.report(error, "bridge error")

    def _refused(self, key: str, record: Tracked, error: StatusError) -> None:
        """The bridge refused a handle's request: the handle fails; awaited or reported."""
        if record.refuse is not None:
            record.refuse(error)
        else:
            record.handle.fail(error)
        event, record.verdict = record.verdict, None
        if event is not None:
            event.set()
        if record.awaited:
            return  # the caller awaiting the handle raises it
        # Reported a moment later unless the handle is awaited first: an in-memory bridge
        # refuses during the call itself, and ``await ros.subscribe(...)`` must raise then too.
        loop = running_loop()
        if loop is None:
            self.report(error, f"bridge refused {key}")
        else:
            record.report = loop.call_soon(self.report, error, f"bridge refused {key}")

    def report(self, error: RosLibError, what: str) -> None:
        """Tell the error hooks (and the log) about an error nobody awaits."""
        if isinstance(error, StatusError):
            record = self._pending.get(str(error.id))
            if record is not None:
                record.report = None
        log.warning("%s: %s", what, error)
        for cb in list(self.error_callbacks):
            try:
                cb(error)
            except Exception:
                log.exception("error callback raised")
