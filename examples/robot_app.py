"""A small robot application on roslibpy_lite: three parts, each an asyncio task.

- a **counter** publishing ``std_msgs/msg/Int16`` on ``/example_counter`` once
  per second, starting at 0;
- an **IMU summer** subscribed to ``sensor_msgs/msg/Imu`` on ``/imu``, adding
  up ``angular_velocity.x`` and printing each value and the running sum;
- a **service** ``/mult_floats`` (``mult_msgs/srv/MultFloats``) answering
  ``x * y``.

Run it against a bridge::

    python -m examples.robot_app --url ws://127.0.0.1:9090

Ctrl+C (or SIGTERM) stops it cleanly with exit status 0.

Each part takes the :class:`~roslibpy_lite.api.Ros` it runs on, so unit
tests hand it a :class:`~roslibpy_lite.mock.MockRos`; the counter also takes
a :class:`Clock`, so a test can play a second in no time.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import signal
import sys
from collections.abc import Callable, Sequence
from typing import Protocol

import roslibpy_lite
from msgs.mult_msgs.srv import MultFloats, MultFloats_Request, MultFloats_Response
from msgs.sensor_msgs.msg import Imu
from msgs.std_msgs.msg import Int16
from roslibpy_lite.api import Ros

__all__ = [
    "COUNTER_TOPIC",
    "DEFAULT_URL",
    "IMU_TOPIC",
    "MULT_SERVICE",
    "Clock",
    "ImuSummer",
    "LoopClock",
    "main",
    "mult_floats",
    "run_app",
    "run_counter",
    "serve_mult_floats",
]

DEFAULT_URL = "ws://127.0.0.1:9090"
COUNTER_TOPIC = "/example_counter"
IMU_TOPIC = "/imu"
MULT_SERVICE = "/mult_floats"

Output = Callable[[str], None]


class Clock(Protocol):
    """What the counter needs of time: read it, and sleep."""

    def time(self) -> float:
        """Seconds on a monotonic scale."""
        ...

    async def sleep(self, seconds: float) -> None:
        """Wait ``seconds``."""
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
    """Adds up ``angular_velocity.x`` of every Imu message it is given."""

    def __init__(self, out: Output | None = _say) -> None:
        self.total = 0.0
        """The running sum."""
        self.count = 0
        """Messages summed."""
        self._out = out

    def add(self, msg: Imu) -> float:
        """Add one message; returns the new sum (and prints value and sum)."""
        x = msg.angular_velocity.x
        self.total += x
        self.count += 1
        if self._out is not None:
            self._out(f"[imu] #{self.count} angular_velocity.x={x:+.4f} sum={self.total:+.4f}")
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


# -- the program --------------------------------------------------------------------------------


async def run_app(
    ros: Ros,
    *,
    stop: asyncio.Event | None = None,
    ready: asyncio.Event | None = None,
    out: Output = _say,
    clock: Clock | None = None,
) -> None:
    """Run the three parts on ``ros`` until ``stop`` is set; a failing part ends them all.

    ``ready`` is set once the subscription and the service are in place.
    """
    stop = stop or asyncio.Event()
    summer = ImuSummer(out)
    subscribed, served = asyncio.Event(), asyncio.Event()
    async with asyncio.TaskGroup() as tg:
        parts = [
            tg.create_task(run_counter(ros, clock=clock, out=out), name="counter"),
            tg.create_task(summer.run(ros, ready=subscribed), name="imu summer"),
            tg.create_task(serve_mult_floats(ros, out=out, ready=served), name="mult_floats"),
        ]
        await subscribed.wait()
        await served.wait()
        if ready is not None:
            ready.set()
        await stop.wait()
        for task in parts:
            task.cancel()


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """The command line."""
    p = argparse.ArgumentParser(
        prog="python -m examples.robot_app",
        description="Counter, IMU summer and /mult_floats service on roslibpy_lite.",
    )
    p.add_argument(
        "--url",
        default=os.environ.get("ROSLIBPY_LITE_URL", DEFAULT_URL),
        help=f"the bridge (default $ROSLIBPY_LITE_URL or {DEFAULT_URL})",
    )
    p.add_argument(
        "--connect-timeout",
        type=float,
        default=30.0,
        help="seconds to keep trying the first connection (default 30)",
    )
    return p.parse_args(argv)


async def _session(args: argparse.Namespace) -> None:
    async with roslibpy_lite.connect(args.url, open_timeout=args.connect_timeout) as ros:
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
        await session
    except asyncio.CancelledError:
        if not stopping:
            raise
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
    _say("[app] stopped")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Run the application; returns the exit status (0 after Ctrl+C)."""
    args = parse_args(argv)
    with contextlib.suppress(KeyboardInterrupt):
        return asyncio.run(_amain(args))
    return 0


if __name__ == "__main__":
    sys.exit(main())
