"""Service ops of one client: call_service, and serving services (advertise_service,
service_response, unadvertise_service).

Service calls
-------------
Each ``call_service`` runs as its own task (at most ``max_calls_in_flight``,
1024, per connection; more fail at once), with ``timeout`` seconds (default
5). Without a type, a service that is not in the ROS graph within
``discovery_wait`` (2 s) fails with "does not exist"; with a type, one the graph
still lists no server of after twice that fails so too (a server started just
before the call can take ~3 s to appear on a loaded machine). A listed service
is waited for (its server to match) up to the call's timeout.
``fragment_size`` on a call splits its ``service_response``. ``/rosapi/*``
services are answered by the bridge itself (:mod:`rosbridge_core.session.rosapi`), and a
service another client of this bridge serves is called directly, without a ROS
hop (so its failure keeps its text).

Client-served services
----------------------
A ROS caller of a service advertised by the client reaches it as
``call_service`` with id ``service_request:<service>:<n>``. If the client
answers ``result: false``, does not answer within ``served_call_timeout``
(10 s) or answers with a response that does not convert, the ROS caller is
not answered (an rclpy service cannot reply with an error, and the bridge
never invents a default response): the caller's own timeout ends its wait.
When the client unadvertises the service or disconnects, the ROS service is
destroyed at once; rclpy callers then see ``service_is_ready()`` turn false,
and requests in flight stay unanswered until the caller's timeout.

Who may serve a name another client (or an rclpy node) serves is decided by
:mod:`rosbridge_core.session.ownership`.
"""

from __future__ import annotations

import asyncio
import functools
import itertools
import json
import logging
import time
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, ClassVar

from rosbridge_core.counters import outcome
from rosbridge_core.interfaces import (
    BridgeError,
    ConversionError,
    ServiceCallError,
    args_mapping,
    canonical_name,
)
from rosbridge_core.protocol import ops
from rosbridge_core.protocol.names import absolute_name
from rosbridge_core.session import rosapi
from rosbridge_core.session.limits import over_cap

if TYPE_CHECKING:
    from rosbridge_core.graph import RosCall, ServedService
    from rosbridge_core.security import Gate
    from rosbridge_core.session.host import SessionView

__all__ = ["ClientService", "SessionServices"]

log = logging.getLogger("bridge_server.session")


class ClientService:
    """A service one client serves, with the callers waiting on it.

    ``pending`` holds the ROS callers, each with the loop time by which the client must
    answer: they all get the same ``served_call_timeout``, so the dict (in the order they
    came) is in the order of their deadlines too, and one timer per session, not one per
    call, ends those the client leaves unanswered (:meth:`SessionServices._expire`).
    ``direct`` holds the calls of other clients of this bridge, each with its own timer
    (their timeouts differ).
    """

    def __init__(self, name: str, type_name: str, spelled: str | None = None) -> None:
        self.name = name
        self.spelled = spelled or name  # the name as the client spelled it
        self.call_head = _call_head(self.spelled)  # each ROS request's op starts with it
        self.type_name = type_name
        self.ros: ServedService | None = None
        self.pending: dict[str, tuple[RosCall, float]] = {}
        self.direct: dict[str, tuple[_DirectCall, asyncio.TimerHandle]] = {}


class _DirectCall:
    """A call from another client of this bridge to a service this client serves.

    It goes from session to session without a ROS hop, so a failure keeps its
    ``result: false`` and text (a ROS service has no way to report one).
    """

    def __init__(self, future: asyncio.Future[tuple[bool, Any]]) -> None:
        self.future = future

    def fail(self, reason: str) -> None:
        if not self.future.done():
            self.future.set_result((False, reason))

    def succeed(self, values: Mapping[str, Any]) -> None:
        if not self.future.done():
            self.future.set_result((True, values))


class SessionServices:
    """One client's service calls in flight and the services it serves."""

    OPS: ClassVar[dict[type[ops.Op], str]] = {
        ops.CallService: "call_service",
        ops.ServiceResponse: "service_response",
        ops.AdvertiseService: "advertise_service",
        ops.UnadvertiseService: "unadvertise_service",
    }
    """The ops this capability carries out, and the method for each."""
    LIMITS: ClassVar[dict[type[ops.Op], str]] = {ops.AdvertiseService: "serve_limit"}
    """The ops that add to what the connection holds, and the method that checks each."""
    RAW_OPS: ClassVar[dict[str, str]] = {"service_response": "answer_decoded"}
    """The op carried out as decoded, in its usual shape (see :meth:`answer_decoded`)."""

    def serve_limit(self, op: ops.AdvertiseService) -> str | None:
        """Why serving one more service would pass the connection's limits."""
        return over_cap(self.served, absolute_name(op.service), self.session.limits.max_services,
                        "served services")

    def __init__(self, session: SessionView) -> None:
        self.session = session
        self.graph = session.graph
        self.served: dict[str, ClientService] = {}
        self._owners = session.shared.service_owners
        self._request_ids = itertools.count()
        self._expiry: asyncio.TimerHandle | None = None  # the earliest ROS caller's deadline

    # -- calling -------------------------------------------------------------------------------

    def call_service(self, op: ops.CallService) -> None:
        """Start the call as its own task, unless too many are in flight already."""
        session = self.session
        limit = session.config.max_calls_in_flight
        if len(session.calls) >= limit:
            self._respond(op.service, op.id, False,
                          f"too many calls in flight on this connection (at most {limit})")
            return
        session.spawn(self._call(op))

    async def _call(self, op: ops.CallService) -> None:
        """Call a ROS service (or a rosapi one) and answer with ``service_response``."""
        service = absolute_name(op.service)
        spelled = op.service  # answer with the name as the client spelled it
        session = self.session
        timeout = op.timeout if op.timeout is not None else session.config.call_timeout
        values: Mapping[str, Any]
        t0 = time.perf_counter()
        try:
            handler = rosapi.HANDLERS.get(service)
            ahandler = rosapi.ASYNC_HANDLERS.get(service)
            if handler is not None:
                values = handler(session.shared, rosapi.request_args(service, op.args))
                values = session.gate.filter_rosapi(service, values)  # what the role may see
            elif ahandler is not None:
                values = await ahandler(session.shared, rosapi.request_args(service, op.args))
                values = session.gate.filter_rosapi(service, values)
            elif (owner := self._owners.get(service)) is not None:
                result, direct = await owner.call_direct(service, op, timeout)
                self._respond(spelled, op.id, result, direct, op.fragment_size, t0)
                return
            else:
                values = await self.graph.call_service(
                    service, op.type, op.args, timeout, session.config.discovery_wait,
                    lambda request: session.actions.cancel_refusal(service, request),
                )
        except (_CallFailed, ServiceCallError) as exc:
            self._respond(spelled, op.id, False, str(exc), op.fragment_size, t0)
            return
        except (BridgeError, rosapi.RosapiError) as exc:
            self._respond(spelled, op.id, False, f"{service}: {exc}", op.fragment_size, t0)
            return
        except UnicodeError:  # a lone surrogate ("\ud800") in a string reached rclpy
            why = f"{service}: a string in args is not valid Unicode text (a lone surrogate?)"
            self._respond(spelled, op.id, False, why, op.fragment_size, t0)
            return
        except Exception as exc:  # answered, never left as an unretrieved task exception
            log.exception("session %d: call to %s failed", session.sid, service)
            why = f"{service}: internal error: {type(exc).__name__}"
            self._respond(spelled, op.id, False, why, op.fragment_size, t0)
            return
        self._respond(spelled, op.id, True, values, op.fragment_size, t0)

    def _respond(
        self,
        service: str,
        id: ops.Id | None,
        result: bool,
        values: Mapping[str, Any] | str,
        fragment_size: int | None = None,
        started: float | None = None,
    ) -> None:
        session = self.session
        if started is not None:  # a call_service: count it for /metrics
            session.shared.metrics.service_call(
                absolute_name(service), outcome(result, values), time.perf_counter() - started
            )
        if not result:
            log.info("session %d: call to %s failed: %s", session.sid, service, values)
        text = ops.encode(ops.ServiceResponse(service=service, result=result, values=values, id=id))
        session.outbox.send_split(text, fragment_size, id, service)

    # -- serving -------------------------------------------------------------------------------

    def advertise_service(self, op: ops.AdvertiseService) -> None:
        """Serve a ROS service from this client."""
        name = absolute_name(op.service)
        srv_cls = self.graph.resolve_service(op.type)
        type_name = canonical_name(op.type, "srv")
        if name in rosapi.HANDLERS or name in rosapi.ASYNC_HANDLERS:
            self.session.error(
                f"advertise_service: {name} is answered by the bridge itself", op.id
            )
            return
        mine = self.served.get(name)
        if mine is not None:
            if mine.type_name == type_name:
                return
            self.remove_served(mine, "the client advertised it again with another type")
            del self.served[name]
        graph = self.graph
        if not self._owners.admit(
            self, op, name, lambda: graph.other_servers(name) if graph.service_types(name) else []
        ):
            return
        served = ClientService(name, type_name, op.service)
        # each ROS request reaches _on_ros_request through a partial: no frame of its own
        served.ros = graph.serve(name, srv_cls, functools.partial(self._on_ros_request, served),
                                 lambda why: self._refused(served, op, why))
        self.served[name] = served
        self._owners.take(name, self)

    def _refused(self, served: ClientService, op: ops.AdvertiseService, why: str) -> None:
        """The graph refused the name after all (a relay's robot keeps another relay's
        client): stop serving it, and refuse the advertise as a second client's is."""
        if self.served.get(served.name) is served:
            del self.served[served.name]
            self.remove_served(served, why)
            self.session.error(f"{op.OP}: {why}", op.id)

    def _on_ros_request(self, served: ClientService, pending: RosCall) -> None:
        session = self.session
        if self.served.get(served.name) is not served or session.closed:
            log.warning("a ROS call to %s arrived after it was unadvertised: not answered",
                        served.name)
            return
        rid = f"service_request:{served.name}:{next(self._request_ids)}"
        try:  # the op's text in one step, the request by its compiled converter
            text = "".join((served.call_head, pending.served.request_conv.to_json(
                pending.request), ',"id":', _encode_str(rid), "}"))
        except Exception:
            log.exception("cannot convert a request to %s", served.name)
            return
        deadline = session.loop.time() + session.config.served_call_timeout
        served.pending[rid] = (pending, deadline)
        if self._expiry is None:
            self._expiry = session.loop.call_at(deadline, self._expire)
        session.outbox.send_text(text)

    def _expire(self) -> None:
        """Forget the ROS callers the client left unanswered past ``served_call_timeout``
        (logged), and wait for the next deadline."""
        self._expiry = None
        now = self.session.loop.time()
        after = None
        for served in self.served.values():
            pending = served.pending
            while pending:
                rid, (_call, deadline) = next(iter(pending.items()))
                if deadline > now:
                    after = deadline if after is None else min(after, deadline)
                    break
                del pending[rid]
                log.warning(
                    "session %d: no answer for %s within %s s; the ROS caller is not answered "
                    "(a ROS service cannot send an error, and the bridge never invents a "
                    "response)", self.session.sid, rid, self.session.config.served_call_timeout,
                )
        if after is not None:
            self._expiry = self.session.loop.call_at(after, self._expire)

    def _direct_timeout(self, served: ClientService, rid: str, timeout: float) -> None:
        entry = served.direct.pop(rid, None)
        if entry is not None:
            entry[0].fail(f"service {served.name} timed out after {timeout} s")

    def service_response(self, op: ops.ServiceResponse) -> None:
        """The client answers a ROS caller of a service it serves (or another client's call)."""
        session = self.session
        name = absolute_name(op.service)
        rid = None if op.id is None else str(op.id)
        served = self.served.get(name)
        if served is None or rid is None or (rid not in served.pending
                                             and rid not in served.direct):
            # the id names the call: answered under another (or no) service name, it is
            # still that call's answer
            served = next((s for s in self.served.values()
                           if rid in s.pending or rid in s.direct), None)
        if served is None or rid is None or served.ros is None:
            session.error(f"service_response: no ROS call {op.id!r} is waiting on {name}", op.id)
            return
        direct = served.direct.pop(rid, None)
        if direct is not None:
            direct[1].cancel()
            if not op.result:
                reason = op.values if isinstance(op.values, str) else "the serving client failed"
                direct[0].fail(f"service {name} failed: {reason}")
                return
            conv = served.ros.response_conv
            try:
                obj = conv.to_obj(conv.from_obj(op.values or {}, "values"))
            except ConversionError as exc:
                session.error(f"service_response for {name}: {exc}", op.id)
                direct[0].fail(f"service {name} answered with a bad response: {exc}")
                return
            direct[0].succeed(obj)
            return
        pending = served.pending.pop(rid)[0]
        if not op.result:
            log.warning(
                "session %d: the client failed %s (%.200s); the ROS caller is not answered "
                "(a ROS service cannot send an error, and the bridge never invents a response)",
                session.sid,
                op.id,
                op.values if isinstance(op.values, str) else "no reason given",
            )
            return
        self._answer(served, pending, op.values if isinstance(op.values, Mapping) else {},
                     op.id)

    def answer_decoded(self, obj: dict[str, Any]) -> bool:
        """``service_response`` as decoded, when it answers a ROS caller in the usual shape
        (``result`` true, ``values`` an object, the ``id`` of a waiting ROS call of that
        service, as this bridge sent it): no op value is made, the generic parse being
        about half of the answer's time in the bridge. Anything else returns False at once,
        untouched, for the generic path (which names what is wrong)."""
        rid = obj.get("id")
        service = obj.get("service")
        values = obj.get("values")
        if (obj.get("result") is not True or type(values) is not dict
                or type(rid) is not str or type(service) is not str):
            return False
        served = self.served.get(service)  # keyed by absolute name, as clients mostly spell it
        if served is None:
            served = self.served.get(absolute_name(service))
        if served is None or served.ros is None:
            return False
        entry = served.pending.pop(rid, None)
        if entry is None:
            return False
        self._answer(served, entry[0], values, rid)
        return True

    def _answer(self, served: ClientService, pending: RosCall, values: Mapping[str, Any],
                op_id: ops.Id | None) -> None:
        """Answer a ROS caller with the client's ``values`` (one that does not convert is
        reported to the client, and the caller left unanswered)."""
        assert served.ros is not None
        try:
            response = served.ros.response_conv.from_obj(values, "values")
        except ConversionError as exc:
            self.session.error(f"service_response for {served.name}: {exc}; the ROS caller "
                               "is not answered", op_id)
            return
        pending.complete(response)

    async def call_direct(
        self, name: str, op: ops.CallService, timeout: float
    ) -> tuple[bool, Any]:
        """Carry out another client's call to a service this client serves (no ROS hop)."""
        served = self.served.get(name)
        if served is None or served.ros is None:
            raise _CallFailed(f"service {name} is no longer served")
        if op.type is not None and canonical_name(op.type, "srv") != served.type_name:
            raise _CallFailed(
                f"service {name} has type {served.type_name}, not {canonical_name(op.type, 'srv')}"
            )
        conv = served.ros.request_conv
        try:
            args = conv.to_obj(conv.from_obj(
                args_mapping(op.args, conv.fields, "request"), "args"))
        except ConversionError as exc:
            raise _CallFailed(f"{name}: bad request: {exc}") from None
        session = self.session
        rid = f"service_request:{name}:{next(self._request_ids)}"
        future: asyncio.Future[tuple[bool, Any]] = session.loop.create_future()
        timer = session.loop.call_later(timeout, self._direct_timeout, served, rid, timeout)
        served.direct[rid] = (_DirectCall(future), timer)
        session.send_op(ops.CallService(service=served.spelled, args=args, id=rid))
        try:
            return await future
        finally:
            entry = served.direct.pop(rid, None)
            if entry is not None:  # the caller went away first
                entry[1].cancel()

    def unadvertise_service(self, op: ops.UnadvertiseService) -> None:
        """Stop serving a service; it leaves ROS at once (waiting ROS callers are not answered)."""
        self._owners.unadvertise(self, op, absolute_name(op.service))

    def remove_served(self, served: ClientService, why: str) -> None:
        """Stop serving ``served``: pending direct calls fail, the ROS service goes."""
        for call, timer in list(served.direct.values()):
            timer.cancel()
            call.fail(f"service {served.name} failed: {why}")
        served.direct.clear()
        unanswered = len(served.pending)
        served.pending.clear()
        if unanswered:
            log.warning("service %s went (%s): %d ROS caller(s) not answered", served.name, why,
                        unanswered)
        if served.ros is not None:
            # At once: ROS callers see the server leave the graph; nobody gets an invented
            # default response (an rclpy service has no way to send an error).
            served.ros.destroy()
            served.ros = None
        self._owners.release(served.name, self)

    def drop_served(self, name: str, why: str) -> None:
        """Another client took the service over: forget it here, and say so."""
        served = self.served.pop(name, None)
        if served is not None:
            self.remove_served(served, why)
            self.session.status("warning", f"service {name}: {why}")

    # -- the session's hooks -------------------------------------------------------------------

    async def close(self) -> None:
        """The client left: its services leave ROS at once (calls are the session's)."""
        for served in list(self.served.values()):
            self.remove_served(served, "the client that served it disconnected")
        self.served.clear()
        if self._expiry is not None:
            self._expiry.cancel()
            self._expiry = None

    def recheck(self, gate: Gate) -> int:
        """Stop serving what the role no longer allows; how many services ended."""
        return self._owners.recheck(self, gate)


class _CallFailed(Exception):
    """A service call failed; the text is sent as the ``service_response`` values."""


_encode_str: Callable[[str], str] = json.encoder.encode_basestring


def _call_head(service: str) -> str:
    """The start of the JSON text of a server-to-client ``call_service`` op (a ROS caller
    reached a service the client serves), up to its ``args``: the request's JSON text, then
    ``,"id":``, the id and ``}`` follow (:meth:`SessionServices._on_ros_request`)."""
    return '{"op":"call_service","service":' + _encode_str(service) + ',"args":'
