"""Unit tests of the sample application's action /integrate_imu on MockRos (no real waits)."""

from __future__ import annotations

import asyncio

import pytest

from examples.robot_app import (
    IMU_TOPIC,
    INTEGRATE_ACTION,
    ImuIntegrator,
    run_app,
    serve_integrate_imu,
)
from msgs.mult_msgs.action import IntegrateImu
from msgs.sensor_msgs.msg import Imu
from roslibpy_lite import MockRos
from roslibpy_lite.actions import ActionError, GoalStatus


class ManualClock:
    """A clock the test moves: sleeps end once :meth:`advance` passes their end."""

    def __init__(self) -> None:
        self.now = 100.0
        self._sleepers: list[tuple[float, asyncio.Future[None]]] = []

    def time(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> asyncio.Future[None]:
        """A future that ends once the clock passes now + ``seconds`` (the end is fixed now)."""
        done: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self._sleepers.append((self.now + seconds, done))
        return done

    def advance(self, seconds: float) -> None:
        self.now += seconds
        for end, done in list(self._sleepers):
            if end <= self.now + 1e-9:
                self._sleepers.remove((end, done))
                if not done.done():
                    done.set_result(None)


def imu(x: float, y: float = 0.0, z: float = 0.0) -> Imu:
    """An Imu message with the given angular velocity."""
    msg = Imu()
    msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z = x, y, z
    return msg


async def serving(ros: MockRos, integrator: ImuIntegrator) -> asyncio.Task[None]:
    """Serve /integrate_imu on ``ros``; returns the task (cancel it to stop)."""
    ready = asyncio.Event()
    task = asyncio.create_task(serve_integrate_imu(ros, integrator, ready=ready))
    await ready.wait()
    return task


async def until(condition: object, what: str) -> None:
    """Let the loop run until ``condition()`` holds (a few hundred turns at most)."""
    for _ in range(500):
        if condition():  # type: ignore[operator]
            return
        await asyncio.sleep(0)
    raise AssertionError(f"never: {what}")


async def test_integrates_angular_velocity_over_the_goal() -> None:
    """Samples 1/8 s apart add w * dt each; feedback after each; result total and samples."""
    ros, clock = MockRos(), ManualClock()
    integrator = ImuIntegrator(clock)
    server = await serving(ros, integrator)
    goal = await ros.send_goal(INTEGRATE_ACTION, IntegrateImu, IntegrateImu.Goal(seconds=0.625))
    await until(lambda: integrator.active == 1, "the goal started")
    for _ in range(4):
        clock.advance(0.125)
        ros.inject(IMU_TOPIC, imu(2.0, -1.0, 0.5))
    clock.advance(0.125)
    outcome = await goal.result(timeout=5)
    assert outcome.status is GoalStatus.SUCCEEDED
    assert outcome.values.samples == 4
    total = outcome.values.total
    assert (total.x, total.y, total.z) == (1.0, -0.5, 0.25)
    feedback = [fb async for fb in goal]
    assert [fb.elapsed for fb in feedback] == [0.125, 0.25, 0.375, 0.5]
    assert [fb.sum.x for fb in feedback] == [0.25, 0.5, 0.75, 1.0]
    server.cancel()


async def test_samples_outside_a_goal_do_not_count() -> None:
    """Only samples during the goal's window count; with none, the total is zero."""
    ros, clock = MockRos(), ManualClock()
    integrator = ImuIntegrator(clock)
    server = await serving(ros, integrator)
    ros.inject(IMU_TOPIC, imu(5.0))
    goal = await ros.send_goal(INTEGRATE_ACTION, IntegrateImu, {"seconds": 1.0})
    await until(lambda: integrator.active == 1, "the goal started")
    clock.advance(1.0)
    outcome = await goal.result(timeout=5)
    ros.inject(IMU_TOPIC, imu(5.0))
    assert outcome.values.samples == 0 and outcome.values.total.x == 0.0
    server.cancel()


async def test_cancel_ends_with_the_partial_result() -> None:
    """A cancel ends the goal at once, CANCELED, with what was integrated so far."""
    ros, clock = MockRos(), ManualClock()
    lines: list[str] = []
    integrator = ImuIntegrator(clock, lines.append)
    server = await serving(ros, integrator)
    goal = await ros.send_goal(INTEGRATE_ACTION, IntegrateImu, {"seconds": 60.0})
    await until(lambda: integrator.active == 1, "the goal started")
    clock.advance(0.5)
    ros.inject(IMU_TOPIC, imu(1.0))
    await goal.cancel()
    outcome = await goal.result(timeout=5)
    assert outcome.status is GoalStatus.CANCELED
    assert outcome.values.samples == 1 and outcome.values.total.x == pytest.approx(0.5)
    assert lines[-1] == f"[action] {INTEGRATE_ACTION}: canceled: total=(+0.5000, +0.0000, " \
                        "+0.0000) samples=1"
    server.cancel()


async def test_two_goals_at_once_integrate_separately() -> None:
    """Two goals overlapping in time each integrate their own window."""
    ros, clock = MockRos(), ManualClock()
    integrator = ImuIntegrator(clock)
    server = await serving(ros, integrator)
    long = await ros.send_goal(INTEGRATE_ACTION, IntegrateImu, {"seconds": 1.0})
    await until(lambda: integrator.active == 1, "the first goal started")
    clock.advance(0.5)
    ros.inject(IMU_TOPIC, imu(1.0))
    short = await ros.send_goal(INTEGRATE_ACTION, IntegrateImu, {"seconds": 0.25})
    await until(lambda: integrator.active == 2, "the second goal started")
    clock.advance(0.125)
    ros.inject(IMU_TOPIC, imu(1.0))
    clock.advance(0.375)
    a, b = await long.result(timeout=5), await short.result(timeout=5)
    assert (a.values.samples, b.values.samples) == (2, 1)
    assert (a.values.total.x, b.values.total.x) == (0.625, 0.125)
    server.cancel()


async def test_a_bad_goal_is_aborted() -> None:
    """A negative duration aborts the goal (the handler raises)."""
    ros = MockRos()
    integrator = ImuIntegrator(ManualClock())
    server = await serving(ros, integrator)
    goal = await ros.send_goal(INTEGRATE_ACTION, IntegrateImu, {"seconds": -1.0})
    with pytest.raises(ActionError, match="ABORTED"):
        await goal.result(timeout=5, raise_on_failure=True)
    server.cancel()


async def test_run_app_serves_the_action_and_stops() -> None:
    """run_app serves /integrate_imu next to the other parts and unadvertises it on stop."""
    ros = MockRos()
    stop, ready = asyncio.Event(), asyncio.Event()
    lines: list[str] = []
    app = asyncio.create_task(run_app(ros, stop=stop, ready=ready, out=lines.append,
                                      clock=ManualClock()))
    await ready.wait()
    assert ros.served_actions() == [INTEGRATE_ACTION]
    goal = await ros.send_goal(INTEGRATE_ACTION, IntegrateImu, {"seconds": 0.0})
    assert (await goal.result(timeout=5)).values.samples == 0
    stop.set()
    await app
    assert f"[action] serving {INTEGRATE_ACTION} (mult_msgs/action/IntegrateImu)" in lines
    assert ros.served_actions() == []
