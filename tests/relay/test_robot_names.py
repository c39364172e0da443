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
from bench.linkproxy import LinkProxy
from bridge_server.zenoh import keys
from bridge_server.zenoh.link import tokens
from tests.helpers import ros_env
from tests.ops.support import aget
from tests.relay.procs import Proc
from tests.relay.support import (
    ROBOT,
    free_port,
    robot_reachable,
    start_relay,
    until,
    until_async,
)

pytestmark = pytest.mark.timeout(90)

ON_ZENOH = re.compile(rf"robot {ROBOT} is on Zenoh \(session (\w+)\)")


def robot_process(router: str, **env: str) -> Proc:
    """A robot's bridge named robot1, dialing out to ``router`` (no websocket)."""
    return Proc([sys.executable, "-m", "bridge_server", "--no-websocket", "--robot", ROBOT,
                 "--zenoh-connect", router], ros_env(**env))


async def refusal_said(relay: Any, holder: Proc, holder_zid: str, refused: Proc,
                       refused_zid: str = r"\w+") -> tuple[str, dict[str, Any]]:
    """Wait for the refused robot's error and the holder's warning naming each other and
    for the relay's count of one refusal; the refused robot's Zenoh id and the relay's
    entry."""
    zid = refused.wait_for(re.compile(
        rf"ERROR .*robot {ROBOT}: another robot holds this name on the Zenoh network "
        rf"\(Zenoh id {holder_zid}\): this robot \(Zenoh id ({refused_zid})\) is refused"))[1]
    holder.wait_for(re.compile(rf"WARNING .*robot {ROBOT}: another robot \(Zenoh id {zid}\) "
                               rf"announced this robot's name, which this robot \(Zenoh id "
                               rf"{holder_zid}\) holds"))
    entry = await until(lambda: relay.names_refused.get(ROBOT), "the relay's count")
    assert entry["count"] == 1, entry
    assert entry["holder"].startswith(f"Zenoh id {holder_zid}"), entry
    assert entry["refused"].startswith(f"Zenoh id {zid}"), entry
    return zid, entry


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
            second_zid, entry = await refusal_said(relay, first, first_zid, second)
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


async def test_a_robot_back_from_an_outage_to_a_taken_name_withdraws(
        ros_node: Any, topic: str) -> None:
    """Robot A holds robot1, its link is cut (a TCP proxy: reset, new connections refused);
    robot B takes the name meanwhile; when A's link is back, A sees B's held claim and
    withdraws with the same error as a second robot at start, the relay counts the refusal
    and goes on serving B: only B's presence token is there, only B answers a query of the
    robot's keys, and a client's call is answered by B's ROS graph."""
    def answer(_request: Any, response: Any) -> Any:
        response.message = "second"
        return response

    ros_node.create_service(Trigger, topic, answer)  # on B's ROS domain, not A's
    port = free_port()
    router = f"tcp/127.0.0.1:{port}"
    relay = await start_relay(listen=router)
    procs: list[Proc] = []
    try:
        with LinkProxy(("127.0.0.1", port)) as link:
            other_domain = str((int(os.environ.get("ROS_DOMAIN_ID", "0")) + 100) % 200)
            first = robot_process(f"tcp/127.0.0.1:{link.port}", ROS_DOMAIN_ID=other_domain)
            procs.append(first)
            first_zid = first.wait_for(ON_ZENOH)[1]
            await robot_reachable(relay, open_it=False)
            link.refuse()
            link.cut()
            first.wait_for(re.compile(rf"robot {ROBOT}: its uplink to the Zenoh network is gone"))
            await until_async(lambda: _absent(relay), "robot1's tokens to leave the relay")

            second = robot_process(router)
            procs.append(second)
            second_zid = second.wait_for(ON_ZENOH)[1]
            link.restore()
            await refusal_said(relay, second, second_zid, first, first_zid)
            await until_async(lambda: _alive(relay, {second_zid}), "only B's presence token")
            assert _graph_answers(relay) == 1  # A's queryables went before its token

            async with roslibpy_lite.connect(f"ws://127.0.0.1:{relay.port}/{ROBOT}") as ros:
                reply = await ros.call_service(topic, "std_srvs/srv/Trigger", {}, timeout=20)
            assert reply["message"] == "second"
            assert sum(1 for line in first.lines if ON_ZENOH.search(line)) == 1, first.lines
    finally:
        for proc in procs:
            proc.stop()
        await relay.close()


async def _absent(relay: Any) -> bool:
    return ROBOT not in await relay.on_network()


async def _alive(relay: Any, zids: set[str]) -> bool:
    """Whether the presence tokens of robot1 on the relay's network are exactly ``zids``'."""
    found = await tokens(relay.session, f"{ROBOT}/{keys.ALIVE}/*", 2.0)
    return {keys.parse_alive(key)[1] for key in found} == zids


def _graph_answers(relay: Any) -> int:
    """How many sessions answer the relay's query of robot1's graph (no consolidation)."""
    import zenoh

    return sum(1 for r in relay.session.get(f"{ROBOT}/{keys.GRAPH}", timeout=5.0,
                                            consolidation=zenoh.ConsolidationMode.NONE) if r.ok)
