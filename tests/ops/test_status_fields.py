"""The bridge's typed status (bridge_server/http/status.py) is the one place a status field is
declared: /status.json's keys, the workers' merge and /metrics all follow its fields, and so
do a relay's per-robot entries and families (bridge_server/zenoh/relay_status.py), with no
bridge running (the live output is checked by test_status_json.py, test_metrics.py and
tests/relay/test_relay_status.py)."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from typing import Any

from prometheus_client.core import Metric
from prometheus_client.exposition import generate_latest
from prometheus_client.parser import text_string_to_metric_families

from bridge_server.http import metrics, snapshot
from bridge_server.http.status import COUNTERS, BridgeStatus
from bridge_server.zenoh.relay_status import EXPORTED, RobotStatus, robot_families, robot_status
from rosbridge_core.session.client_status import ClientStatus, SubscriptionStatus
from tests.helpers import ROOT

P = "roslibpy_bridge_"


def _count_fields() -> list[dataclasses.Field[Any]]:
    """BridgeStatus's number fields but the worker's index: the counts."""
    return [f for f in dataclasses.fields(BridgeStatus) if f.type == "int" and f.name != "worker"]


def _status(base: int) -> BridgeStatus:
    """A status whose every number field is a value of its own (base + its position)."""
    client = ClientStatus(
        id="0-1", sid=1, worker=0, protocol="rosbridge", address="127.0.0.1:1",
        connected_at=1.0, subscriptions=(SubscriptionStatus("/t", None, 1, 10, 2, 3),),
        publishes=("/p",), serves=(), calls_in_flight=0, parked=False, queued=1, dropped=2,
        resume_kept=4)
    counts: dict[str, Any] = {f.name: base + i for i, f in enumerate(_count_fields())}
    return BridgeStatus(version="v", worker=0, workers=[], started=1.0, refused={}, errors={},
                        service_calls={}, action_goals={}, topics={}, clients=(client,),
                        services=[], actions=[], **counts)


def test_every_count_field_reaches_the_json_the_merge_and_the_metrics() -> None:
    """Each count field of BridgeStatus (an int, but the worker's index) is a key of
    /status.json, is summed over workers, and is exported as the counter <field>_total with
    its help."""
    one, two = _status(100), _status(1000)
    assert [f.name for f in _count_fields()] == [c.name for c in COUNTERS]  # all counter()
    assert list(one.to_json()) == [f.name for f in dataclasses.fields(BridgeStatus)]
    merged = snapshot.merge([one.to_json(), two.to_json()])
    exported = {family.name: family for family in text_string_to_metric_families(
        metrics.render(merged, metrics.new_caps()).decode())}
    for count in COUNTERS:
        want = getattr(one, count.name) + getattr(two, count.name)
        assert merged[count.name] == want, count.name
        family = exported.get(P + count.name)
        assert family is not None, f"{count.name} is not in /metrics"
        assert (family.type, family.documentation) == ("counter", count.help), count.name
        assert [s.value for s in family.samples if s.name.endswith("_total")] == [want]


def test_the_docs_metrics_tables_have_a_row_for_every_count_field() -> None:
    """README's and the operations page's metrics tables name each count field's counter
    (test_docs.py checks them against a live bridge; this needs none)."""
    for page in (ROOT / "README.md", ROOT / "docs" / "operations.md"):
        table = page.read_text().split("Metrics (all `roslibpy_bridge_*`):")[1].split("\n\n")[1]
        missing = [c.name for c in COUNTERS if f"`{c.name}_total`" not in table]
        assert missing == [], page.name


def test_a_client_status_is_its_json_entry() -> None:
    """A ClientStatus's JSON entry has its fields as keys, in order, subscriptions included,
    and its queue and resume counts reach the per-client metrics."""
    snap = _status(0).to_json()
    entry = snap["clients"][0]
    assert list(entry) == [f.name for f in dataclasses.fields(ClientStatus)]
    assert list(entry["subscriptions"][0]) == [f.name for f in dataclasses.fields(
        SubscriptionStatus)]
    assert entry["publishes"] == ["/p"] and entry["serves"] == []
    text = metrics.render(snap, metrics.new_caps()).decode()
    assert f'{P}client_queued_messages{{client="0-1"}} 1.0' in text
    assert f'{P}resume_kept_frames{{client="0-1"}} 4.0' in text


def _robot(name: str, *, served: bool, base: int) -> RobotStatus:
    """A robot whose exported numbers are values of their own (base + 1, base + 2, ...)."""
    return robot_status(name, present=True, snap={} if served else None,
                        bytes_from_robot=base + 1 if served else 0,
                        dropped={"bad_graph": base + 2, "messages_lost": base + 3}
                        if served else {})


def test_every_exported_robot_field_reaches_the_relays_json_and_metrics() -> None:
    """Each field of the relay's RobotStatus is a key of its robots' entries, in order, and
    each one made with robot_metric is the family it names, with its help, one series per
    robot (and per kind), for every robot or only the served ones as it says."""
    robots = [_robot("a", served=True, base=10), _robot("b", served=False, base=20)]
    assert list(robots[0].to_json()) == [f.name for f in dataclasses.fields(RobotStatus)]
    exported = {family.name: family for family in text_string_to_metric_families(
        generate_latest(_Families(robots)).decode())}
    assert len(EXPORTED) >= 3
    for field, m in EXPORTED:
        family = exported.get("roslibpy_relay_" + m.name)
        assert family is not None, f"{field} is not in /metrics"
        assert (family.type, family.documentation) == (m.kind, m.help), field
        names = ["robot"] if m.label is None else ["robot", m.label]
        got = {tuple(s.labels[n] for n in names): s.value for s in family.samples
               if not s.name.endswith("_created")}
        want: dict[tuple[str, ...], float] = {}
        for robot in robots:
            if m.every_robot or robot.served:
                value = getattr(robot, field)
                if m.label is None:
                    want[(robot.name,)] = int(value)
                else:
                    want.update({(robot.name, k): n for k, n in value.items()})
        assert got == want, field


class _Families:
    """A collector of the relay's per-robot families (what generate_latest asks for)."""

    def __init__(self, robots: list[RobotStatus]) -> None:
        self.robots = robots

    def collect(self) -> Iterator[Metric]:
        return robot_families(self.robots)
