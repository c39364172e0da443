"""Calling ROS services from the loop: cached clients, waiting for a matched server, the
first requests on a newly matched client, and answers handed back to the loop.

:class:`ServiceCalls` is the part of :class:`~.node.RosNode` that calls services; both
:meth:`ServiceCalls.call_when_ready` and the sessions' typed calls
(:meth:`~.graph.RclpyGraph.call_service`) wait for a server with one helper,
:meth:`ServiceCalls.wait_for_server`.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable
from typing import Any

from bridge_server.rclpy_graph.qos import SERVICE_DEPTH, qos_profile

__all__ = ["RESEND_S", "SETTLE_S", "ServiceCalls"]

RESEND_S = 0.1
"""Seconds a read-only request on a newly matched client waits for its answer before it is
sent again (see call_when_ready): a server drops an answer when it has not matched our
response reader within 100 ms of the request."""

SETTLE_S = 1.2
"""Seconds a newly matched service client waits before its first request (see settled).

The server drops its answer if it has not matched our response reader within 100 ms of the
request (rmw_fastrtps: the response writer's max blocking time). Discovery normally takes
milliseconds, but one lost discovery sample is repaired only on Fast DDS's next discovery
heartbeat (1 s, answered after 100 ms): 0.5 s did not cover that, and CI lost first answers
that way. Paid once per service and type for the bridge's life (clients are kept)."""


class ServiceCalls:
    """Service calls of the bridge's node (a base of :class:`~.node.RosNode`, which sets the
    attributes below and hands results to the loop with :meth:`post`)."""

    loop: asyncio.AbstractEventLoop
    node: Any
    _clients: dict[tuple[str, type[Any]], Any]

    def post(self, fn: Callable[..., None], *args: Any) -> None:
        """Run ``fn(*args)`` on the loop thread soon (callable from any thread)."""
        raise NotImplementedError

    def client_for(self, service: str, srv_cls: type[Any]) -> Any:
        """A cached rclpy client for ``service`` of ``srv_cls``."""
        key = (service, srv_cls)
        client = self._clients.get(key)
        if client is None:
            client = self._clients[key] = self.node.create_client(
                srv_cls, service, qos_profile=qos_profile(True, False, SERVICE_DEPTH)
            )
            _inline_done_callbacks(client)
        return client

    async def settled(self, client: Any) -> None:
        """Return once ``client`` has had a matched server for :data:`SETTLE_S` seconds.

        DDS matches each direction of a service on its own: the bridge can see a server as
        ready (our request writer and response reader matched) before the server has
        matched our response reader, and a request sent in that window is executed but its
        answer lost (rmw_fastrtps: "failed to send response"). Nothing on our side shows the
        server's half, so the first requests on a newly matched client wait a moment; later
        calls on the same client do not wait at all.
        """
        now = self.loop.time()
        since = getattr(client, "_bridge_ready_at", None)
        if since is None:
            since = now
            client._bridge_ready_at = since
        wait = since + SETTLE_S - now
        if wait > 0:
            await asyncio.sleep(wait)

    async def wait_for_server(
        self, service: str, srv_cls: type[Any], deadline: float, unlisted_by: float
    ) -> Any:
        """The cached client of ``service`` once it has a matched server (a new one where
        another call dropped the cached client meanwhile), polling with a backoff from 2 ms
        to 50 ms.

        Raises ``LookupError`` once the loop's time passes ``unlisted_by`` with no server in
        the ROS graph, ``TimeoutError`` once it passes ``deadline``.
        """
        loop = self.loop
        client = self.client_for(service, srv_cls)
        delay = 0.002
        while not _ready(client):
            if loop.time() >= unlisted_by and self.server_count(service) == 0:
                raise LookupError(f"service {service} does not exist (not in the ROS graph)")
            if _ready(client) is None:  # another call dropped the cached client
                client = self.client_for(service, srv_cls)
            if loop.time() >= deadline:
                raise TimeoutError(f"service {service} is not available")
            await asyncio.sleep(delay)
            delay = min(delay * 2, 0.05)
        return client

    async def call_when_ready(
        self,
        service: str,
        srv_cls: type[Any],
        request: Any,
        timeout: float,
        discovery_wait: float | None = None,
        *,
        read_only: bool = False,
    ) -> Any:
        """Call ``service`` once a server is matched; ``TimeoutError`` after ``timeout`` s.

        With ``discovery_wait``, a service the ROS graph still does not list after that
        many seconds fails then (``LookupError``), not after the whole timeout.
        ``read_only`` (a request that may run twice, such as listing or reading parameters):
        a newly matched client sends at once and again after :data:`RESEND_S` (backing off)
        until an answer comes, instead of waiting :data:`SETTLE_S` before its first request.
        """
        loop = self.loop
        deadline = loop.time() + timeout
        unlisted_by = loop.time() + (discovery_wait if discovery_wait is not None else timeout)
        client = await self.wait_for_server(service, srv_cls, deadline, unlisted_by)
        if read_only and getattr(client, "_bridge_ready_at", None) is None:
            return await self._resent(client, request, deadline, service)
        await self.settled(client)
        future = self.call(client, request)
        timer = loop.call_at(deadline, _fail_timeout, future)
        try:
            return await future
        finally:
            timer.cancel()

    async def _resent(self, client: Any, request: Any, deadline: float, service: str) -> Any:
        """The answer to a read-only ``request`` on a client not settled yet: sent again
        after RESEND_S, then twice as long each time up to 1 s (an answer the server sent
        before it matched our reader is lost) until one comes; the client counts as settled
        from then on."""
        loop = self.loop
        every = RESEND_S
        while True:
            future = self.call(client, request)
            wait = min(every, deadline - loop.time())
            every = min(every * 2, 1.0)  # a server that is slow, not deaf: ask less often
            try:
                response = await asyncio.wait_for(asyncio.shield(future), max(wait, 0.0))
            except TimeoutError:
                future.cancel()  # forgets the request: a late answer to it is dropped
                if loop.time() >= deadline:
                    raise TimeoutError(f"service {service} did not answer") from None
                continue
            client._bridge_ready_at = loop.time() - SETTLE_S  # answered: settled
            return response

    def drop_client(self, service: str, srv_cls: type[Any]) -> None:
        """Destroy the cached client (after a call found no server)."""
        client = self._clients.pop((service, srv_cls), None)
        if client is not None:
            with contextlib.suppress(Exception):
                self.node.destroy_client(client)

    def server_count(self, service: str) -> int:
        """How many servers of ``service`` the graph knows."""
        return int(self.node.count_services(service))

    def call(self, client: Any, request: Any) -> asyncio.Future[Any]:
        """Send ``request`` now; the returned asyncio future gets the response.

        Cancelling the returned future (or failing it, e.g. on a timeout) forgets the
        pending request.
        """
        loop = self.loop
        result: asyncio.Future[Any] = loop.create_future()
        rfuture = client.call_async(request)

        def done(f: Any) -> None:
            exc = f.exception()
            self.post(_settle, result, exc, None if exc is not None else f.result())

        rfuture.add_done_callback(done)

        def forget(f: asyncio.Future[Any]) -> None:
            if f.cancelled() or f.exception() is not None:
                with contextlib.suppress(Exception):
                    client.remove_pending_request(rfuture)

        result.add_done_callback(forget)
        return result

def _ready(client: Any) -> bool | None:
    """Whether ``client`` has a matched server; None once the client was destroyed."""
    try:
        return bool(client.service_is_ready())
    except Exception:  # rclpy's InvalidHandle: dropped by another call in the meantime
        return None


class _InlineFuture:
    """What the executor gets for a pending request: completing it runs the done callbacks
    right there, instead of scheduling each as an executor task (two more wait-set rounds
    per call)."""

    __slots__ = ("_future",)

    def __init__(self, future: Any) -> None:
        self._future = future

    def _set_executor(self, executor: Any) -> None:
        pass

    def set_result(self, result: Any) -> None:
        self._future.set_result(result)

    def set_exception(self, exc: BaseException) -> None:
        self._future.set_exception(exc)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._future, name)


def _inline_done_callbacks(client: Any) -> None:
    get = client.get_pending_request

    def get_pending_request(sequence_number: int) -> Any:
        return _InlineFuture(get(sequence_number))

    client.get_pending_request = get_pending_request


def _fail_timeout(fut: asyncio.Future[Any]) -> None:
    if not fut.done():
        fut.set_exception(TimeoutError("the service did not answer in time"))


def _settle(fut: asyncio.Future[Any], exc: BaseException | None, value: Any) -> None:
    if fut.done():
        return
    if exc is not None:
        fut.set_exception(exc)
    else:
        fut.set_result(value)
