"""One robot's line in a relay's status, typed: its entry of ``robots`` in the relay's
``/status.json`` and its series of the relay's own ``/metrics`` families.

:class:`RobotStatus`'s fields, in their order, are the entry's keys
(:meth:`RobotStatus.to_json`). A field the relay also exports is made with
:func:`robot_metric` metadata, which names the family (``roslibpy_relay_<name>``), its type and
help, and for a field counted by kind the label of that kind; :func:`robot_families`
builds those families from the fields, so a new exported field is one typed field.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any, Literal

from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric

__all__ = ["RobotMetric", "RobotStatus", "robot_families", "robot_metric", "robot_status",
           "robots_refused", "robots_refused_family"]

PREFIX = "roslibpy_relay_"
_METRIC = "metric"


@dataclass(frozen=True)
class RobotMetric:
    """How a field of :class:`RobotStatus` is exported (one series per robot)."""

    name: str
    """The family is ``roslibpy_relay_<name>`` (a counter's samples end in ``_total``)."""
    kind: Literal["gauge", "counter"]
    help: str
    label: str | None
    """For a field of counts by kind (a dict): the label naming the kind."""
    every_robot: bool
    """Exported for every robot listed; else only for the robots the relay serves."""


def robot_metric(name: str, kind: Literal["gauge", "counter"], help: str, *,
                 label: str | None = None, every_robot: bool = False) -> dict[str, RobotMetric]:
    """The metadata of a field of :class:`RobotStatus` that the relay's ``/metrics`` exports
    too (``dataclasses.field(metadata=robot_metric(...))``)."""
    return {_METRIC: RobotMetric(name, kind, help, label, every_robot)}


@dataclass(frozen=True, kw_only=True)
class RobotStatus:
    """One robot as the relay's page and ``/metrics`` show it."""

    name: str
    present: bool = dataclasses.field(metadata=robot_metric(
        "robot_present", "gauge",
        "1 while the robot is on this relay's Zenoh network, 0 once it went away.",
        every_robot=True))
    served: bool
    """The relay has the robot's bridge open (a client or a viewer used it)."""
    clients: int
    """Connected clients (kept sessions not counted)."""
    clients_by_protocol: dict[str, int]
    topics_watched: list[str]
    """Topics at least one client subscribes to."""
    messages_from_robot: int
    messages_to_clients: int
    bytes_to_clients: int
    messages_from_clients: int
    bytes_from_clients: int
    drops: int
    """Messages dropped from clients' full queues."""
    bytes_from_robot: int = dataclasses.field(metadata=robot_metric(
        "bytes_from_robot", "counter",
        "Payload bytes of the robot's topic messages this relay received from Zenoh."))
    dropped: dict[str, int] = dataclasses.field(metadata=robot_metric(
        "robot_dropped", "counter",
        "What a robot sent that the relay dropped, by kind: messages_dropped (oldest, over "
        "its queue), messages_lost (past its replay window in a link outage), "
        "replies_dropped, graph_too_large, graph_superseded, bad_graph, "
        "bad_messages, type_refused (its type over --max-definition-bytes or "
        "--max-types-per-robot), not_holder (put by a robot refused the name), bad_replies, "
        "handling_failed.", label="kind"))

    def to_json(self) -> dict[str, Any]:
        """The robot's entry in the relay's ``/status.json`` (keys are the field names)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}


EXPORTED: tuple[tuple[str, RobotMetric], ...] = tuple(
    (f.name, f.metadata[_METRIC]) for f in dataclasses.fields(RobotStatus)
    if _METRIC in f.metadata)
"""The fields of :class:`RobotStatus` the relay exports, with how, in their order."""


def robot_status(name: str, *, present: bool, snap: Mapping[str, Any] | None,
                 bytes_from_robot: int, dropped: dict[str, int]) -> RobotStatus:
    """A robot's status from its bridge's (visible) snapshot (``None``: the relay does not
    serve it) and what the relay counted of it."""
    topics: Mapping[str, Mapping[str, Any]] = (snap or {}).get("topics", {})

    def total(field: str) -> int:
        return int(sum(t.get(field, 0) for t in topics.values()))

    clients = [c for c in (snap or {}).get("clients", []) if not c.get("parked")]
    return RobotStatus(
        name=name, present=present, served=snap is not None,
        clients=len(clients),
        clients_by_protocol={p: sum(1 for c in clients if c.get("protocol") == p)
                             for p in sorted({c.get("protocol", "rosbridge")
                                              for c in clients})},
        topics_watched=sorted(name for name, t in topics.items() if t.get("subscribers")),
        messages_from_robot=total("ros_received"),
        messages_to_clients=total("sent"),
        bytes_to_clients=total("sent_bytes"),
        messages_from_clients=total("published"),
        bytes_from_clients=total("published_bytes"),
        drops=total("drops"),
        bytes_from_robot=bytes_from_robot,
        dropped=dropped,
    )


def robot_families(robots: Iterable[RobotStatus]) -> Iterator[Metric]:
    """The relay's per-robot families (:data:`EXPORTED`), each series labelled ``robot``."""
    robots = list(robots)
    for field, m in EXPORTED:
        labels = ["robot"] if m.label is None else ["robot", m.label]
        family = (GaugeMetricFamily if m.kind == "gauge" else CounterMetricFamily)(
            PREFIX + m.name, m.help, labels=labels)
        for robot in robots:
            if not (m.every_robot or robot.served):
                continue
            value = getattr(robot, field)
            if m.label is None:
                family.add_metric([robot.name], int(value))
            else:
                for kind, n in sorted(value.items()):
                    family.add_metric([robot.name, kind], n)
        yield family


def robots_refused(snapshot: Mapping[str, Any], may_see: Callable[[str], bool]
                   ) -> dict[str, Any]:
    """The ``robots_refused`` entry of the relay's ``/status.json``: refusals of robots by
    the relay's router, counted by reason (every viewer), and the last of each robot name
    ``may_see`` lets this viewer see (reason, why with what to fix, peer, count, last)."""
    return {"counts": dict(snapshot.get("counts", {})),
            "robots": {name: entry for name, entry in snapshot.get("robots", {}).items()
                       if may_see(name)}}


def robots_refused_family(snapshot: Mapping[str, Any]) -> Metric:
    """``roslibpy_relay_robots_refused_total`` by reason (the relay's ``/metrics``)."""
    family = CounterMetricFamily(
        PREFIX + "robots_refused",
        "Robots the relay's router did not admit, by reason (not_named: its certificate's "
        "name is not in --zenoh-robot; other_name: its certificate is for another robot; "
        "no_certificate; unknown_ca; key_usage; tls_refused).", labels=["reason"])
    for reason, n in sorted(snapshot.get("counts", {}).items()):
        family.add_metric([reason], n)
    return family
