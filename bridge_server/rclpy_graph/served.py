"""Client-served services: real ROS services answered by a websocket client.

A client-served service is a real ROS service whose response is deferred: it is
sent from the loop when the client answers, fails, times out or goes away (see
:class:`PendingRosCall`). With the loop reader the middleware wakes the loop for each
request, which takes it itself and answers it on the loop (:class:`ServedService`,
:class:`LoopRosCall`); otherwise it is an rclpy service whose callback returns at once, so the
executor is never blocked.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
import warnings
from collections.abc import Callable
from typing import Any, Protocol

from bridge_server.rclpy_graph import convert
from bridge_server.rclpy_graph.qos import SERVICE_DEPTH, qos_profile
from bridge_server.rclpy_graph.reader import LoopReader, Reader, ReaderService

__all__ = [
    "ANSWER_RETRIES",
    "UNMATCHED_CALLER",
    "LoopRosCall",
    "PendingRosCall",
    "ServedService",
    "ServingNode",
]

log = logging.getLogger("bridge_server.rclpy_graph.node")  # the name it always logged under


class ServingNode(Protocol):
    """What a served service uses of the bridge's node (:class:`~.node.RosNode`)."""

    @property
    def loop(self) -> asyncio.AbstractEventLoop:
        """The asyncio loop the sessions run on."""

    @property
    def node(self) -> Any:
        """The rclpy node."""

    @property
    def reader(self) -> Reader | None:
        """What takes the topics' messages (``None`` before start)."""

    def post(self, fn: Callable[..., None], *args: Any) -> None:
        """Run ``fn(*args)`` on the loop thread soon."""


class PendingRosCall:
    """A ROS caller waiting for a client-served service's answer.

    The rclpy callback returns this object at once; rclpy then hands it with
    the request header to the service's ``send_response``, which the bridge
    intercepts. Whichever of (header, answer) arrives second sends the real
    response, from whichever thread that is.
    """

    def __init__(self, served: ServedService, request: Any) -> None:
        self.served = served
        self.request = request
        self._lock = threading.Lock()
        self._header: Any = None
        self._response: Any = None
        self.done = False

    def _attach(self, header: Any) -> None:
        with self._lock:
            self._header = header
            response = self._response
        if response is not None:
            self.served._send(response, header)

    def complete(self, response: Any | None = None) -> bool:
        """Answer the ROS caller (``None``: a default response). False if already answered."""
        if self.done:
            return False
        self.done = True
        if response is None:
            response = self.served.srv_cls.Response()
        with self._lock:
            self._response = response
            header = self._header
        if header is not None:
            self.served._send(response, header)
        return True


class LoopRosCall:
    """A ROS caller of a service the loop reader serves: taken on the loop with its header,
    answered on the loop, so unlike :class:`PendingRosCall` it needs no lock."""

    __slots__ = ("done", "header", "request", "served")

    def __init__(self, served: ServedService, request: Any, header: Any) -> None:
        self.served = served
        self.request = request
        self.header = header
        self.done = False

    def complete(self, response: Any | None = None) -> bool:
        """Answer the ROS caller (``None``: a default response). False if already answered."""
        if self.done:
            return False
        self.done = True
        served = self.served
        served._send(response if response is not None else served.srv_cls.Response(),
                     self.header)
        return True


UNMATCHED_CALLER = "client will not receive response"
"""rmw_fastrtps's words when it drops an answer: the service's reply writer has not matched
the caller's reply reader within its ``max_blocking_time`` (100 ms); rclpy says so with a
RuntimeWarning, not an exception."""

ANSWER_RETRIES = (0.1, 0.2, 0.4, 0.8, 1.6, 3.2)
"""Seconds before each new attempt to answer a ROS caller whose reply reader the bridge has
not matched yet (6.3 s in all; each attempt may wait 100 ms in rmw_fastrtps).

A caller's ``wait_for_service`` is true once the caller's side has matched the service's
two topics, which says nothing of the bridge's side (it is true even while the bridge is
stopped with SIGSTOP); a caller that calls at once can get its answer sent before the
bridge's discovery has seen the caller's reply reader, and on a loaded machine that takes
more than the 100 ms rmw_fastrtps waits: the answer was lost and the caller waited for
ever (issue 43, test_served_service_comes_back_after_bridge_restart)."""

_SENDING = threading.Lock()
"""Held while an answer is sent with the warnings caught (catch_warnings is process-wide)."""


class ServedService:
    """A ROS service whose requests are answered by a websocket client.

    With the loop reader (:class:`~bridge_server.rclpy_graph.reader.LoopReader`) the middleware
    wakes the loop for each request, which takes it with its header and answers it on the
    loop: no executor round, no thread between the caller and the client. Otherwise the
    service is rclpy's, served by the executor's thread as :class:`PendingRosCall` says.
    """

    def __init__(
        self,
        ros: ServingNode,
        name: str,
        srv_cls: type[Any],
        on_request: Callable[[PendingRosCall | LoopRosCall], None],
    ) -> None:
        self.ros = ros
        self.name = name
        self.srv_cls = srv_cls
        self.request_conv = convert.converter_for(srv_cls.Request)
        self.response_conv = convert.converter_for(srv_cls.Response)
        self.on_request = on_request
        qos = qos_profile(True, False, SERVICE_DEPTH)
        reader = ros.reader
        self._served: ReaderService | None = None
        if isinstance(reader, LoopReader):
            self._served = reader.serve(srv_cls, name, qos, self._on_loop_request)
            self._real_send: Callable[[Any, Any], None] = self._served.respond
            return
        post = ros.post

        def callback(request: Any, _response: Any) -> Any:
            pending = PendingRosCall(self, request)
            post(self.on_request, pending)
            return pending

        self.srv: Any = ros.node.create_service(srv_cls, name, callback, qos_profile=qos)
        self._real_send = self.srv.send_response

        def send_response(response: Any, header: Any) -> None:
            if isinstance(response, PendingRosCall):
                response._attach(header)
            else:
                self._real_send(response, header)

        self.srv.send_response = send_response

    def _on_loop_request(self, request: Any, header: Any) -> None:
        self.on_request(LoopRosCall(self, request, header))

    def _send(self, response: Any, header: Any, attempt: int = 0) -> None:
        """Answer a ROS caller; again later while its reply reader is not matched here yet
        (see :data:`ANSWER_RETRIES`), from the loop."""
        with _SENDING, warnings.catch_warnings(record=True) as warned:
            warnings.simplefilter("always", RuntimeWarning)
            try:
                self._real_send(response, header)
            except Exception as exc:  # destroyed meanwhile, or the caller went away
                log.debug("could not answer a ROS caller of %s: %s", self.name, exc)
                return
        if not warned or not any(UNMATCHED_CALLER in str(w.message) for w in warned):
            return
        if attempt < len(ANSWER_RETRIES):
            loop = self.ros.loop
            with contextlib.suppress(RuntimeError):  # the loop closed while shutting down
                loop.call_soon_threadsafe(loop.call_later, ANSWER_RETRIES[attempt], self._send,
                                          response, header, attempt + 1)
            return
        log.warning("could not answer a ROS caller of %s: its reply reader never matched "
                    "the bridge's reply writer (%d tries over %.1f s; incompatible QoS?)",
                    self.name, attempt + 1, sum(ANSWER_RETRIES))

    def destroy(self) -> None:
        """Remove the ROS service."""
        if self._served is not None:
            reader = self.ros.reader
            if isinstance(reader, LoopReader):
                reader.unserve(self._served)
            return
        with contextlib.suppress(Exception):
            self.ros.node.destroy_service(self.srv)

