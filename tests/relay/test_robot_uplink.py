"""The robot's own log says when its uplink to the Zenoh network goes and comes back."""

from __future__ import annotations

import logging

import pytest

from tests.relay.support import free_port, start_relay, start_robot, until

pytestmark = pytest.mark.timeout(120)


async def test_the_robot_logs_its_uplink_going_and_coming_back(
        caplog: pytest.LogCaptureFixture) -> None:
    """A robot whose only router (a relay) stops logs at WARNING that its uplink is gone,
    and at INFO that it is back once the router is up again on the same endpoint."""
    caplog.set_level(logging.INFO, logger="bridge_server.zenoh.exporter")
    router = f"tcp/127.0.0.1:{free_port()}"
    relay = await start_relay(listen=router)
    robot, exporter = await start_robot(router)
    try:
        await until(lambda: exporter.uplinks, "the robot to reach its router")
        await relay.close()
        await until(lambda: exporter.uplink_lost == 1, "the robot to see its uplink go")
        gone = [r for r in caplog.records if "uplink to the Zenoh network is gone" in r.message]
        assert len(gone) == 1 and gone[0].levelno == logging.WARNING, caplog.text
        assert "robot robot1:" in gone[0].message
        relay = await start_relay(listen=router)
        await until(lambda: exporter.uplinks, "the robot to dial its router again", 30)
        back = [r for r in caplog.records if "uplink to the Zenoh network is back" in r.message]
        assert len(back) == 1 and back[0].levelno == logging.INFO, caplog.text
    finally:
        await relay.close()
        await exporter.close()
        await robot.close()
