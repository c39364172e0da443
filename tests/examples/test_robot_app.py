"""Unit tests of the sample application's parts on MockRos: no network, no ROS, no real waits."""

from __future__ import annotations

import asyncio
import itertools
import math
from typing import Any

import pytest

from examples import robot_app
from examples.robot_app import (
    COUNTER_TOPIC,
    IMU_TOPIC,
    MULT_SERVICE,
    ImuSummer,
    mult_floats,
    run_app,
    run_counter,
    serve_mult_floats,
)
from msgs.mult_msgs.srv import MultFloats, MultFloats_Request
from msgs.sensor_msgs.msg import Imu
from roslibpy_lite import MockRos, ServiceError


class FakeClock:
    """A clock whose sleeps take no real time: each one moves ``now`` forward."""

    def __init__(self, start: float = 100.0) -> None:
        self.now = start
        self.sleeps: list[float] = []

    def time(self) -> float:
        return self.now

    async def sleep(self, seconds: float) -> None:
        self.sleeps.append(seconds)
        self.now += seconds
        await asyncio.sleep(0)


class StuckClock(FakeClock):
    """A clock whose sleeps never end (the counter publishes once, then waits for cancellation)."""

    def __init__(self) -> None:
        super().__init__()
        self.sleeping = asyncio.Event()

    async def sleep(self, seconds: float) -> None:
        self.sleeps.append(seconds)
        self.sleeping.set()
        await asyncio.Event().wait()


def imu(x: float) -> Imu:
    """An Imu message with angular_velocity.x = x."""
    msg = Imu()
    msg.angular_velocity.x = x
    return msg


async def test_counter_publishes_0_1_2_one_period_apart() -> None:
    """The counter publishes Int16 0, 1, 2 in order, one period apart on the injected clock."""
    ros = MockRos()
    clock = FakeClock()
    seen: list[tuple[int, float]] = []
    ros.subscribe(COUNTER_TOPIC, "std_msgs/msg/Int16",
                  lambda m: seen.append((m["data"], clock.time())))
    await run_counter(ros, clock=clock, count=3)
    assert [v for v, _ in seen] == [0, 1, 2]
    assert [round(b[1] - a[1], 9) for a, b in itertools.pairwise(seen)] == [1.0, 1.0]
    assert ros.published(COUNTER_TOPIC) == [{"data": 0}, {"data": 1}, {"data": 2}]


async def test_counter_period_is_configurable() -> None:
    """With period 0.25 the ticks are 0.25 s apart on the injected clock."""
    ros = MockRos()
    clock = FakeClock()
    times: list[float] = []
    ros.subscribe(COUNTER_TOPIC, "std_msgs/msg/Int16", lambda m: times.append(clock.time()))
    await run_counter(ros, clock=clock, count=4, period=0.25)
    assert [t - times[0] for t in times] == [0.0, 0.25, 0.5, 0.75]


async def test_counter_keeps_its_grid_when_publishing_takes_time() -> None:
    """Time spent publishing is taken off the next sleep, so ticks stay on start + n * period."""
    ros = MockRos()
    clock = FakeClock(start=0.0)
    times: list[float] = []

    def slow_subscriber(msg: Any) -> None:
        times.append(clock.time())
        clock.now += 0.3  # publishing "took" 0.3 s

    ros.subscribe(COUNTER_TOPIC, "std_msgs/msg/Int16", slow_subscriber)
    await run_counter(ros, clock=clock, count=3)
    assert times == [0.0, 1.0, 2.0]
    assert clock.sleeps == [pytest.approx(0.7), pytest.approx(0.7)]


async def test_counter_wraps_like_int16() -> None:
    """Values stay in Int16's range: 32767 is followed by -32768 (the mock checks the type)."""
    ros = MockRos()
    await run_counter(ros, clock=FakeClock(), count=3, start=32766)
    assert ros.published(COUNTER_TOPIC) == [{"data": 32766}, {"data": 32767}, {"data": -32768}]


async def test_counter_unadvertises_when_cancelled() -> None:
    """Cancelling the counter while it sleeps ends it without an error."""
    ros = MockRos()
    clock = StuckClock()
    task = asyncio.create_task(run_counter(ros, clock=clock))
    await clock.sleeping.wait()  # the first sleep starts once 0 is published
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    assert ros.published(COUNTER_TOPIC) == [{"data": 0}]


async def test_imu_summer_adds_angular_velocity_x_and_prints_each() -> None:
    """The summer adds angular_velocity.x of each Imu and prints the value and the running sum
    (of each message, with every=0)."""
    ros = MockRos()
    lines: list[str] = []
    summer = ImuSummer(lines.append, every=0)
    ready = asyncio.Event()
    task = asyncio.create_task(summer.run(ros, count=3, ready=ready))
    await ready.wait()
    for x in (0.5, -0.25, 1.0):
        ros.inject(IMU_TOPIC, imu(x))
    total = await task
    assert total == pytest.approx(1.25)
    assert summer.count == 3
    assert lines == [
        "[imu] #1 angular_velocity.x=+0.5000 sum=+0.5000",
        "[imu] #2 angular_velocity.x=-0.2500 sum=+0.2500",
        "[imu] #3 angular_velocity.x=+1.0000 sum=+1.2500",
    ]
    assert ros.subscribers(IMU_TOPIC) == 0


async def test_imu_summer_accepts_dict_messages_from_the_wire() -> None:
    """Messages injected in wire (dict) form are decoded to Imu and summed too."""
    ros = MockRos()
    summer = ImuSummer(None)
    ready = asyncio.Event()
    task = asyncio.create_task(summer.run(ros, count=2, ready=ready))
    await ready.wait()
    ros.inject(IMU_TOPIC, {"angular_velocity": {"x": 2.0, "y": 0.0, "z": 0.0}},
               "sensor_msgs/msg/Imu")
    ros.inject(IMU_TOPIC, {"angular_velocity": {"x": 3.5}}, "sensor_msgs/msg/Imu")
    assert await task == pytest.approx(5.5)


def test_imu_summer_prints_a_line_a_second_of_a_50_hz_imu() -> None:
    """Three seconds of a 50 Hz IMU make three lines (the first message's, then one a second),
    each with the running sum of every message."""
    clock = FakeClock(start=100.0)
    lines: list[str] = []
    summer = ImuSummer(lines.append, clock=clock)
    for i in range(150):
        clock.now = 100.0 + i / 50
        summer.add(imu(0.5))
    assert summer.count == 150 and summer.total == pytest.approx(75.0)
    assert lines == [
        "[imu] #1 angular_velocity.x=+0.5000 sum=+0.5000",
        "[imu] #51 angular_velocity.x=+0.5000 sum=+25.5000",
        "[imu] #101 angular_velocity.x=+0.5000 sum=+50.5000",
    ]


def test_imu_summer_handles_nan() -> None:
    """A NaN reading (null on the wire) makes the sum NaN and is still printed, not a crash."""
    lines: list[str] = []
    summer = ImuSummer(lines.append)
    summer.add(Imu.from_json({"angular_velocity": {"x": None}}))
    assert math.isnan(summer.total)
    assert lines == ["[imu] #1 angular_velocity.x=+nan sum=+nan"]


def test_mult_floats_multiplies() -> None:
    """The handler answers x * y."""
    assert mult_floats(MultFloats_Request(x=2.5, y=4.0)).result == 10.0
    assert mult_floats(MultFloats_Request(x=-3.0, y=0.5)).result == -1.5


async def test_mult_floats_service_answers_calls() -> None:
    """/mult_floats served on MockRos answers typed and dict calls with x * y."""
    ros = MockRos()
    ready = asyncio.Event()
    lines: list[str] = []
    task = asyncio.create_task(serve_mult_floats(ros, out=lines.append, ready=ready))
    await ready.wait()
    typed = await ros.call_service(MULT_SERVICE, MultFloats, MultFloats_Request(x=2.5, y=4.0))
    assert typed.result == 10.0
    plain = await ros.call_service(MULT_SERVICE, "mult_msgs/srv/MultFloats", {"x": 3.0, "y": 7.0})
    assert plain == {"result": 21.0}
    assert lines[-1] == "[service] /mult_floats: 3.0 * 7.0 = 21.0"
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    assert ros.served() == []
    with pytest.raises(ServiceError, match="does not exist"):
        await ros.call_service(MULT_SERVICE, MultFloats, {"x": 1.0, "y": 1.0})


async def test_run_app_runs_all_parts_and_stops_on_request() -> None:
    """run_app starts counter, summer and service together and returns cleanly once stop is set."""
    ros = MockRos()
    stop = asyncio.Event()
    lines: list[str] = []
    clock = StuckClock()
    ready = asyncio.Event()
    app = asyncio.create_task(run_app(ros, stop=stop, ready=ready, out=lines.append, clock=clock))
    await ready.wait()
    await clock.sleeping.wait()
    assert ros.published(COUNTER_TOPIC) == [{"data": 0}]
    ros.inject(IMU_TOPIC, imu(0.75))
    assert (await ros.call_service(MULT_SERVICE, MultFloats, {"x": 2.0, "y": 8.0})).result == 16.0
    stop.set()
    await app
    assert "[imu] #1 angular_velocity.x=+0.7500 sum=+0.7500" in lines
    assert ros.served() == [] and ros.subscribers(IMU_TOPIC) == 0


def test_main_reports_an_unreachable_bridge(capsys: pytest.CaptureFixture[str]) -> None:
    """With no bridge listening, main() prints one line on stderr and returns 1."""
    code = robot_app.main(["--url", "ws://127.0.0.1:9", "--connect-timeout", "0.2"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1
    assert len(err) == 1 and err[0].startswith("robot_app: cannot connect to ws://127.0.0.1:9")
