"""One robot per name (issue 38, item 2): a second robot announcing a name another live robot
holds is refused, and everyone says so.

A relay (the Zenoh router, in this process) and two real robot bridges in child processes
(``python -m bridge_server --robot robot1 --zenoh-connect ...``), the second on a ROS domain of
its own, so a call it answered could not reach the service of this test's ROS node.
"""

from __future__ import annotations

import json
import os
import re
import sys
from typing import Any

import pytest
from std_srvs.srv import Trigger

import roslibpy_lite
from tests.helpers import ros_env
from tests.ops.support import aget
from tests.relay.procs import Proc
from tests.relay.support import ROBOT, free_port, robot_reachable, start_relay, until

pytestmark = pytest.mark.timeout(90)

ON_ZENOH = re.compile(rf"robot {ROBOT} is on Zenoh \(session (\w+)\)")


def robot_process(router: str, **env: str) -> Proc:
    """A robot's bridge named robot1, dialing out to ``router`` (no websocket)."""
    return Proc([sys.executable, "-m", "bridge_server", "--no-websocket", "--robot", ROBOT,
                 "--zenoh-connect", router], ros_env(**env))


async def test_a_second_robot_with_a_held_name_is_refused(
        ros_node: Any, topic: str, caplog: pytest.LogCaptureFixture) -> None:
    """A second robot1 while the first is live: it logs an error naming both Zenoh ids and
    serves nothing on Zenoh; the first logs the refused one and goes on; the relay logs both
    with their addresses and counts the refusal in /status.json and /metrics; a client's call
    through the relay is answered by the first robot's ROS graph. Once the first leaves, the
    second takes the name."""
    def answer(_request: Any, response: Any) -> Any:
        response.message = "first"
        return response

    ros_node.create_service(Trigger, topic, answer)
    router = f"tcp/127.0.0.1:{free_port()}"
    relay = await start_relay(listen=router)
    first = robot_process(router)
    second: Proc | None = None
    try:
        first_zid = first.wait_for(ON_ZENOH)[1]
        await robot_reachable(relay)
        url = f"ws://127.0.0.1:{relay.port}/{ROBOT}"
        async with roslibpy_lite.connect(url) as ros:
            reply = await ros.call_service(topic, "std_srvs/srv/Trigger", {}, timeout=20)
            assert reply["message"] == "first"

            other_domain = str((int(os.environ.get("ROS_DOMAIN_ID", "0")) + 100) % 200)
            second = robot_process(router, ROS_DOMAIN_ID=other_domain)
            refused = second.wait_for(re.compile(
                rf"ERROR .*robot {ROBOT}: another robot holds this name on the Zenoh network "
                rf"\(Zenoh id {first_zid}\): this robot \(Zenoh id (\w+)\) is refused"))
            second_zid = refused[1]
            first.wait_for(re.compile(rf"WARNING .*robot {ROBOT}: another robot \(Zenoh id "
                                      rf"{second_zid}\) announced this robot's name, which "
                                      rf"this robot \(Zenoh id {first_zid}\) holds"))
            entry = await until(lambda: relay.names_refused.get(ROBOT), "the relay's count")
            assert entry["count"] == 1, entry
            assert entry["holder"].startswith(f"Zenoh id {first_zid} at tcp/127.0.0.1:"), entry
            assert entry["refused"].startswith(f"Zenoh id {second_zid} at tcp/127.0.0.1:"), entry
            said = [r for r in caplog.records if r.name == "bridge_server.relay"
                    and r.getMessage().startswith(f"refused robot {ROBOT} ")]
            assert [r.getMessage() for r in said] == [
                f"refused robot {ROBOT} ({entry['refused']}): robot {ROBOT} ({entry['holder']}) "
                "holds that name; this relay goes on serving it"], caplog.text

            code, _, body = await aget(f"http://127.0.0.1:{relay.port}/status.json")
            assert code == 200 and json.loads(body)["names_refused"] == {ROBOT: entry}, body
            code, _, body = await aget(f"http://127.0.0.1:{relay.port}/metrics")
            assert code == 200 and \
                f'roslibpy_relay_robot_names_refused_total{{robot="{ROBOT}"}} 1.0' in \
                body.decode(), body

            reply = await ros.call_service(topic, "std_srvs/srv/Trigger", {}, timeout=20)
            assert reply["message"] == "first"
            assert second.proc.poll() is None
            assert not any(ON_ZENOH.search(line) for line in second.lines), second.lines

        first.stop()
        second.wait_for(re.compile(rf"robot {ROBOT}: the robot that held its name left; "
                                   rf"this robot \(Zenoh id {second_zid}\) takes it"))
        assert second.wait_for(ON_ZENOH)[1] == second_zid
    finally:
        for proc in (first, second):
            if proc is not None:
                proc.stop()
        await relay.close()
