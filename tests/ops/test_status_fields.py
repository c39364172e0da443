"""The bridge's typed status (bridge_server/http/status.py) is the one place a status field is
declared: /status.json's keys, the workers' merge and /metrics all follow its fields, with no
bridge running (the live output is checked by test_status_json.py and test_metrics.py)."""

from __future__ import annotations

import dataclasses
from typing import Any

from prometheus_client.parser import text_string_to_metric_families

from bridge_server.http import metrics, snapshot
from bridge_server.http.status import COUNTERS, BridgeStatus
from bridge_server.session.client_status import ClientStatus, SubscriptionStatus
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
