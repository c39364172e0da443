"""A small robot application on roslibpy_lite: three parts, each an asyncio task.

- a **counter** publishing ``std_msgs/msg/Int16`` on ``/example_counter`` once
  per second, starting at 0;
- an **IMU summer** subscribed to ``sensor_msgs/msg/Imu`` on ``/imu``, adding
  up ``angular_velocity.x`` and printing the value and the running sum once a
  second (the IMU publishes at 50 Hz);
- a **service** ``/mult_floats`` (``mult_msgs/srv/MultFloats``) answering
  ``x * y``;
- an **action** ``/integrate_imu`` (``mult_msgs/action/IntegrateImu``):
  integrates the IMU's angular velocity over the goal's ``seconds``, with
  feedback (the running integral and the time so far) after each IMU sample,
  and the total and the number of samples as the result.

Run it against a bridge::

    python -m examples.robot_app --url ws://127.0.0.1:9090

Ctrl+C (or SIGTERM) stops it cleanly with exit status 0.

Each part takes the :class:`~roslibpy_lite.api.Ros` it runs on, so unit
tests hand it a :class:`~roslibpy_lite.mock.MockRos`; the counter and the
integrator also take a :class:`Clock`, so a test can play a second in no time.

Send the action a goal from the shell (``--feedback`` prints the running sum)::

    roslibpy-lite action send_goal /integrate_imu mult_msgs/action/IntegrateImu \
        "{seconds: 2.0}" --feedback
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import math
import os
import signal
import sys
import time
from collections.abc import Awaitable, Callable, Sequence
from typing import Protocol

import roslibpy_lite
from msgs.geometry_msgs.msg import Vector3
from msgs.mult_msgs.action import IntegrateImu, IntegrateImu_Goal, IntegrateImu_Result
from msgs.mult_msgs.srv import MultFloats, MultFloats_Request, MultFloats_Response
from msgs.sensor_msgs.msg import Imu
from msgs.std_msgs.msg import Int16
from roslibpy_lite.actions import GoalContext
from roslibpy_lite.api import Ros

__all__ = [
    "COUNTER_TOPIC",
    "DEFAULT_URL",
    "IMU_TOPIC",
    "INTEGRATE_ACTION",
    "MULT_SERVICE",
    "Clock",
    "ImuIntegrator",
    "ImuSummer",
    "LoopClock",
    "main",
    "mult_floats",
    "run_app",
    "run_counter",
    "serve_integrate_imu",
    "serve_mult_floats",
]

DEFAULT_URL = "ws://127.0.0.1:9090"
COUNTER_TOPIC = "/example_counter"
IMU_TOPIC = "/imu"
MULT_SERVICE = "/mult_floats"
INTEGRATE_ACTION = "/integrate_imu"

Output = Callable[[str], None]


class Clock(Protocol):
    """What the counter needs of time: read it, and sleep."""

    def time(self) -> float:
        """Seconds on a monotonic scale."""
        ...

    def sleep(self, seconds: float) -> Awaitable[None]:
        """Wait ``seconds`` (``await clock.sleep(s)``)."""
        ...


class LoopClock:
    """The running event loop's clock (the real one)."""

    def time(self) -> float:
        """The loop's monotonic time."""
        return asyncio.get_running_loop().time()

    async def sleep(self, seconds: float) -> None:
        """``asyncio.sleep``."""
        await asyncio.sleep(seconds)


def _say(text: str) -> None:
    print(text, flush=True)


# -- the counter --------------------------------------------------------------------------------


async def run_counter(
    ros: Ros,
    *,
    topic: str = COUNTER_TOPIC,
    period: float = 1.0,
    clock: Clock | None = None,
    count: int | None = None,
    start: int = 0,
    out: Output | None = None,
) -> None:
    """Publish ``start``, ``start + 1``, ... on ``topic`` (std_msgs/msg/Int16), one per ``period``.

    Ticks are scheduled on a fixed grid (first tick + n * period), so the rate
    does not drift with the time publishing takes. Stops after ``count``
    messages (None: runs until cancelled); the value wraps from 32767 to -32768.
    """
    clock = clock or LoopClock()
    async with ros.advertise(topic, Int16) as pub:
        first = clock.time()
        n = 0
        while count is None or n < count:
            value = (start + n + 2**15) % 2**16 - 2**15
            await pub.publish(Int16(data=value))
            if out is not None:
                out(f"[counter] published {value} on {topic}")
            n += 1
            if count is not None and n >= count:
                break
            delay = first + n * period - clock.time()
            if delay > 0:
                await clock.sleep(delay)


# -- the IMU summer -----------------------------------------------------------------------------


class ImuSummer:
    """Adds up ``angular_velocity.x`` of every Imu message it is given.

    It prints the first message's value and sum, then the latest ones at most once per
    ``every`` seconds (0: every message), so a 50 Hz IMU makes a line a second.
    """

    def __init__(self, out: Output | None = _say, *, every: float = 1.0,
                 clock: Clock | None = None) -> None:
        self.total = 0.0
        """The running sum."""
        self.count = 0
        """Messages summed."""
        self._out = out
        self._every = every
        self._now = clock.time if clock is not None else time.monotonic
        self._printed_at: float | None = None

    def add(self, msg: Imu) -> float:
        """Add one message; returns the new sum (and prints value and sum when it is time)."""
        x = msg.angular_velocity.x
        self.total += x
        self.count += 1
        if self._out is not None:
            now = self._now()
            if self._printed_at is None or now - self._printed_at >= self._every:
                self._printed_at = now
                self._out(f"[imu] #{self.count} angular_velocity.x={x:+.4f} "
                          f"sum={self.total:+.4f}")
        return self.total

    async def run(
        self,
        ros: Ros,
        *,
        topic: str = IMU_TOPIC,
        count: int | None = None,
        ready: asyncio.Event | None = None,
    ) -> float:
        """Subscribe to ``topic`` and sum until cancelled (or ``count`` messages); the sum.

        ``ready`` is set once the subscription is made.
        """
        async with ros.subscribe(topic, Imu, queue_length=10) as sub:
            if ready is not None:
                ready.set()
            async for msg in sub:
                self.add(msg)
                if count is not None and self.count >= count:
                    break
        return self.total


# -- the service --------------------------------------------------------------------------------


def mult_floats(request: MultFloats_Request) -> MultFloats_Response:
    """The /mult_floats handler: ``x * y``."""
    return MultFloats_Response(result=request.x * request.y)


async def serve_mult_floats(
    ros: Ros,
    *,
    service: str = MULT_SERVICE,
    out: Output | None = None,
    ready: asyncio.Event | None = None,
) -> None:
    """Serve ``service`` (mult_msgs/srv/MultFloats) until cancelled; sets ``ready`` once served."""

    def handler(request: MultFloats_Request) -> MultFloats_Response:
        response = mult_floats(request)
        if out is not None:
            out(f"[service] {service}: {request.x} * {request.y} = {response.result}")
        return response

    async with ros.advertise_service(service, MultFloats, handler):
        if out is not None:
            out(f"[service] serving {service} (mult_msgs/srv/MultFloats)")
        if ready is not None:
            ready.set()
        await asyncio.Event().wait()


# -- the action ---------------------------------------------------------------------------------


class _Window:
    """One goal's integration: the running sums since ``start``."""

    def __init__(self, ctx: GoalContext, start: float) -> None:
        self.ctx = ctx
        self.start = start
        self.last = start
        self.sum = [0.0, 0.0, 0.0]
        self.samples = 0
        self.wake = asyncio.Event()

    def add(self, msg: Imu, now: float) -> None:
        w = msg.angular_velocity
        dt = now - self.last
        self.last = now
        for i, value in enumerate((w.x, w.y, w.z)):
            self.sum[i] += value * dt
        self.samples += 1
        self.ctx.publish_feedback(IntegrateImu.Feedback(sum=self.vector(),
                                                        elapsed=now - self.start))
        self.wake.set()

    def vector(self) -> Vector3:
        return Vector3(x=self.sum[0], y=self.sum[1], z=self.sum[2])


class ImuIntegrator:
    """Integrates the IMU's angular velocity for the goals of ``/integrate_imu``.

    Feed it every Imu message (:meth:`add`); :meth:`integrate` is the action
    handler. Each sample adds ``angular_velocity * dt`` (``dt``: the time since
    the previous sample of the goal, or since its start), and sends feedback.
    A goal ends after ``seconds`` on the clock, or early when canceled (its
    partial result then ends it CANCELED). Several goals may run at once.
    """

    def __init__(self, clock: Clock | None = None, out: Output | None = None) -> None:
        self._clock = clock or LoopClock()
        self._out = out
        self._windows: list[_Window] = []

    @property
    def active(self) -> int:
        """Goals being integrated now."""
        return len(self._windows)

    def add(self, msg: Imu) -> None:
        """One IMU sample, for every goal running now."""
        now = self._clock.time()
        for window in list(self._windows):
            window.add(msg, now)

    async def integrate(self, goal: IntegrateImu_Goal, ctx: GoalContext) -> IntegrateImu_Result:
        """The action handler: integrate for ``goal.seconds``; the total and the sample count."""
        if not (math.isfinite(goal.seconds) and goal.seconds >= 0):
            raise ValueError(f"seconds must be a finite number >= 0, got {goal.seconds}")
        clock = self._clock
        window = _Window(ctx, clock.time())
        end = window.start + goal.seconds
        self._windows.append(window)
        if self._out is not None:
            self._out(f"[action] {ctx.action}: integrating for {goal.seconds} s")
        try:
            while not ctx.cancel_requested:
                remaining = end - clock.time()
                if remaining <= 0:
                    break
                window.wake.clear()
                waits = [asyncio.ensure_future(w) for w in
                         (clock.sleep(remaining), window.wake.wait(), ctx.wait_cancel())]
                try:
                    await asyncio.wait(waits, return_when=asyncio.FIRST_COMPLETED)
                finally:
                    for w in waits:
                        w.cancel()
        finally:
            self._windows.remove(window)
        result = IntegrateImu_Result(total=window.vector(), samples=window.samples)
        if self._out is not None:
            t = result.total
            ended = "canceled" if ctx.cancel_requested else "done"
            self._out(f"[action] {ctx.action}: {ended}: total=({t.x:+.4f}, {t.y:+.4f}, "
                      f"{t.z:+.4f}) samples={result.samples}")
        return result


async def serve_integrate_imu(
    ros: Ros,
    integrator: ImuIntegrator,
    *,
    action: str = INTEGRATE_ACTION,
    topic: str = IMU_TOPIC,
    out: Output | None = None,
    ready: asyncio.Event | None = None,
) -> None:
    """Serve ``action`` with ``integrator`` fed from ``topic``, until cancelled."""
    async with (
        ros.subscribe(topic, Imu, integrator.add, queue_length=10),
        ros.advertise_action(action, IntegrateImu, integrator.integrate),
    ):
        if out is not None:
            out(f"[action] serving {action} (mult_msgs/action/IntegrateImu)")
        if ready is not None:
            ready.set()
        await asyncio.Event().wait()


# -- the program --------------------------------------------------------------------------------


async def run_app(
    ros: Ros,
    *,
    stop: asyncio.Event | None = None,
    ready: asyncio.Event | None = None,
    out: Output = _say,
    clock: Clock | None = None,
) -> None:
    """Run the four parts on ``ros`` until ``stop`` is set; a failing part ends them all.

    ``ready`` is set once the subscription, the service and the action are in place.
    """
    stop = stop or asyncio.Event()
    summer = ImuSummer(out, clock=clock)
    integrator = ImuIntegrator(clock, out)
    subscribed, served, acting = asyncio.Event(), asyncio.Event(), asyncio.Event()
    async with asyncio.TaskGroup() as tg:
        parts = [
            tg.create_task(run_counter(ros, clock=clock, out=out), name="counter"),
            tg.create_task(summer.run(ros, ready=subscribed), name="imu summer"),
            tg.create_task(serve_mult_floats(ros, out=out, ready=served), name="mult_floats"),
            tg.create_task(serve_integrate_imu(ros, integrator, out=out, ready=acting),
                           name="integrate_imu"),
        ]
        await subscribed.wait()
        await served.wait()
        await acting.wait()
        if ready is not None:
            ready.set()
        await stop.wait()
        for task in parts:
            task.cancel()


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """The command line."""
    p = argparse.ArgumentParser(
        prog="python -m examples.robot_app",
        description="Counter, IMU summer, /mult_floats service and /integrate_imu action "
                    "on roslibpy_lite.",
    )
    p.add_argument(
        "--url",
        default=os.environ.get("ROSLIBPY_LITE_URL", DEFAULT_URL),
        help=f"the bridge (default $ROSLIBPY_LITE_URL or {DEFAULT_URL})",
    )
    p.add_argument(
        "--token",
        default=os.environ.get("ROSLIBPY_LITE_TOKEN"),
        help="token for a bridge that requires one (default $ROSLIBPY_LITE_TOKEN)",
    )
    p.add_argument(
        "--cafile",
        default=os.environ.get("ROSLIBPY_LITE_CAFILE"),
        help="CA file for a wss:// bridge with a private CA (default $ROSLIBPY_LITE_CAFILE)",
    )
    p.add_argument(
        "--connect-timeout",
        type=float,
        default=30.0,
        help="seconds to keep trying the first connection (default 30)",
    )
    return p.parse_args(argv)


async def _session(args: argparse.Namespace) -> None:
    secure = args.url.startswith("wss://")
    async with roslibpy_lite.connect(args.url, open_timeout=args.connect_timeout,
                                     token=args.token,
                                     ssl=args.cafile if secure else None) as ros:
        _say(f"[app] connected to {args.url}")
        await run_app(ros)


async def _amain(args: argparse.Namespace) -> int:
    loop = asyncio.get_running_loop()
    session = loop.create_task(_session(args))
    stopping = False

    def stop() -> None:
        nonlocal stopping
        stopping = True
        session.cancel()

    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop)
    try:
        try:
            await session
        except asyncio.CancelledError:
            if not stopping:
                raise
        # Said while our handlers are still installed: a second SIGINT (a terminal's
        # Ctrl+C reaches the whole process group, and demo.sh then sends its own) must
        # not become a KeyboardInterrupt that swallows this line.
        _say("[app] stopped")
        return 0
    except roslibpy_lite.RosLibError as exc:
        print(f"robot_app: {exc}", file=sys.stderr, flush=True)
        return 1
    except ExceptionGroup as group:
        first = group.exceptions[0]
        print(f"robot_app: {type(first).__name__}: {first}", file=sys.stderr, flush=True)
        return 1
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the application; returns the exit status (0 after Ctrl+C)."""
    args = parse_args(argv)
    with contextlib.suppress(KeyboardInterrupt):
        return asyncio.run(_amain(args))
    return 0


if __name__ == "__main__":
    sys.exit(main())
