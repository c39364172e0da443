"""End-to-end benchmarks of the bridge, printed as JSON (one object per scenario, then a summary).

Run: ``python -m bench [--scenario all|NAME ...] [--duration S] [--quick] [--profile]``
(every option: ``python -m bench --help``). Nothing here asserts anything about time.

Each scenario starts its own bridge (``python -m bridge_server`` on
127.0.0.1, ephemeral port, a private ``ROS_DOMAIN_ID``); the ROS side of each
scenario runs in its own process (``bench/ros_side.py``), so the figures
measure the bridge. Clients are raw ``websockets`` connections (not our client
library), and they count frames without decoding big payloads.

Scenarios (targets; rosbridge_suite's figures in brackets):

- ``rclpy_ceiling`` (``bench/ceiling.py``): one rclpy publisher process -> one rclpy
  subscriber process, no bridge: what the ROS side alone can carry (small strings, and the
  ``image`` scenario's 640x480 images into a raw subscriber that deserialises nothing).
- ``ros_to_client`` (``bench/small.py``): highest rate of small std_msgs/String (step search,
  on a ladder to 40,000 msg/s) where >= 99 % reach a websocket client. Target 8,000 msg/s
  [500].
- ``ros_to_client_raw``: the same with ``compression: cbor-raw`` (the client gets the CDR
  bytes as the bridge took them).
- ``client_to_ros``: the same from a websocket client to an rclpy subscriber.
  Target 10,000 msg/s [5,000].
- ``service`` (``bench/services.py``): call_service round trip to an rclpy SetBool service:
  p50 of sequential calls (target <= 1 ms) and calls/s with 16 in flight (target
  >= 1,000) [3.7 ms; 74 calls/s].
- ``client_service``: the mirror of ``service``: a websocket client serves SetBool, an rclpy
  client calls it through the bridge: p50/p99 of sequential calls, calls/s with 16 in flight.
- ``latency`` (``bench/latency.py``): one-way ROS -> client latency at 200 Hz, p50/p99
  (target p99 <= 1 ms) [1.6 ms].
- ``latency_side_by_side``: the same for our bridge and rosbridge_server_rs in one run,
  one publisher taking turns between their topics (and a plain rclpy subscriber's).
- ``image`` (``bench/images.py``): 640x480 rgb8 sensor_msgs/Image from an rclpy publisher as
  fast as it goes to one client; frames that reached the client in order per second of
  publishing, as JSON (target 60), CBOR (target 400) and cbor-raw [14; 360], beside the ROS
  ceiling (the same publisher into a raw rclpy subscriber, no bridge, measured the same way
  in the same run).
- ``idle_cpu`` (``bench/footprint.py``): the bridge's CPU with one connected client (target
  < 1 % of a core) [~5 %].
- ``memory_stall``: the bridge's RSS while one client stalls under an image
  flood: start, peak, end [rosbridge grew 400 MB in 6 s].
- ``pointcloud`` (``bench/cloud.py``): a 4 MiB PointCloud2 at 10 Hz to 5 clients, CBOR
  and cbor-raw: delivered per client, the bridge's CPU and RSS.
- ``relay_uplink`` (``bench/relay.py``): a 640x480 camera at 10 Hz to 1, 10, 50, 100
  viewers through a relay (the robot dials out over Zenoh) and straight to the bridge: the
  robot's uplink bytes against one viewer's, frames delivered, relay and robot CPU.
- ``relay_service`` (``bench/relay.py``): call_service round trips to an rclpy SetBool
  service through a relay and straight to the robot's bridge, in alternating blocks: p50/p99.
- ``relay_imu`` (``bench/relay.py``): a 100 Hz sensor_msgs/Imu to 200 JSON viewers (50 with
  ``--quick``) over two relays: the fraction delivered, latency p50/p99, the relays' CPU per
  message.
- ``fanout`` (``bench/fanout.py``): a 50 Hz topic to 100 and 200 JSON viewers of one
  bridge and of one relay, and a 10 Hz 640x480 camera to 100 cbor-raw viewers of one relay;
  the viewers run in processes of their own and count frames without decoding them:
  delivered, the server's CPU per delivered message (target <= 10 us), the write floor.
- ``relay_dead_link`` (``bench/relay.py``): a robot's Zenoh link blackholed (no FIN) while a
  viewer watches through the relay: seconds until the viewer's "went away" status, and until
  "is back" once restored, with ``--zenoh-lease 3`` (the default) and 10 (Zenoh's own).
- ``relay_outage`` (``bench/relay.py``): a robot's Zenoh link blackholed for 5, 15 and 60 s
  (5 and 15 with ``--quick``) while a reliable 10 Hz topic flows through a relay, with the
  default replay window (300 messages): messages lost, seconds from the restore to the last
  missed message delivered, the robot's RSS and window bytes during the outage.
- ``tls`` (``bench/tls.py``): small messages, service round trips and CBOR images over ws://
  and over wss://, side by side (reference only).
- ``workers_resume`` (``bench/workers.py``): with ``--workers 2``, call_service round trips
  through a resumed connection that its worker forwarded to the session's worker, against
  a direct one, over ws:// and wss://: p50/p99 of each (reference only).
- ``params`` (``bench/params.py``): ``ros.graph.params()`` on a graph with a node lacking
  parameter services: the first call and the median of the next (targets: warm < 50 ms,
  cold < 300 ms) [2.03 s on every call].
- ``links`` (``bench/links.py``): through ``bench/linkproxy.py``: a silent link (how soon
  each side notices), a 2 Mbit/s link (the age of the camera frames a client gets) and a
  resume across an 8 s outage (what each side got).
- ``record`` (``bench/bag.py``): ``roslibpy-lite bag record`` in its own process, a
  640x480 camera at 30 Hz plus an IMU at 200 Hz for 60 s: what the file holds against what
  was published, the recorder's CPU and write rate; then the camera alone at rising rates.
- ``foxglove`` (``bench/foxglove.py``): the Foxglove path against the rosbridge cbor-raw path
  on one bridge: 640x480 images at the publisher's pace and small messages per second to one
  client, and one 30 Hz camera to 10 viewers (the bridge's CPU per frame).
- ``action_ros_server`` / ``action_client_served`` (``bench/actions.py``): goal
  round trip p50/p99 and feedback throughput, to an rclpy action server and to a
  client-served action driven by an rclpy action client.
- ``fleet`` (``bench/fleet.py``): simulated robots (``bench/simrobot.py``: the bridge's own
  exporter over an in-memory graph), Zenoh routers in a mesh, relays behind HAProxy, many
  viewers: cost per unwatched robot, watched robot and viewer, open wait, delivery, flood
  isolation, recovery after a relay kill and a router restart, join/leave churn
  (``BENCH_FLEET_SIZES`` picks the sizes; docs/guides/sizing.md has the figures).

``--profile`` runs py-spy on the bridge during ``ros_to_client``, ``image``, ``service`` and
``client_service``, on the recorder during ``record``'s camera and IMU, and in ``fleet`` on
the first relay (its steady window, a read of its status page) and on it and the first robot
process after the router's restart, and adds the top functions (self and inclusive samples)
to their results (``bench/profiler.py``). Frames are counted without decoding them
(``bench/counting.py``).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import platform
import sys
import time
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bench.actions import action_client_served, action_ros_server
from bench.bag import record
from bench.ceiling import rclpy_ceiling
from bench.cloud import pointcloud
from bench.compare import COMPARE_SCENARIOS, compare
from bench.fanout import fanout
from bench.fleet import fleet
from bench.footprint import idle_cpu, memory_stall
from bench.foxglove import foxglove
from bench.harness import CODE_ROOT, Ctx
from bench.images import image
from bench.latency import latency, latency_side_by_side
from bench.links import links
from bench.params import params_scenario
from bench.relay import relay_dead_link, relay_imu, relay_outage, relay_service, relay_uplink
from bench.services import client_service, service
from bench.small import client_to_ros, ros_to_client
from bench.tls import tls_scenario
from bench.workers import workers_resume

TARGETS: dict[str, str] = {
    "rclpy_ceiling": "reference only",
    "ros_to_client": ">= 8,000 msg/s at >= 99 % (no less than 5,000) [rosbridge 500]",
    "ros_to_client_raw": "the same with compression cbor-raw: >= 40,000 msg/s at >= 99 %",
    "client_to_ros": ">= 10,000 msg/s at >= 99 % [rosbridge 5,000]",
    "service": "p50 <= 1 ms, >= 1,000 calls/s with 16 in flight [rosbridge 3.7 ms, 74/s]",
    "client_service": "p50 and p99 at or below rosbridge_server_rs's (--peer rs)",
    "latency": "p99 <= 1 ms at 200 Hz [rosbridge 1.6 ms]",
    "latency_side_by_side": "p50 and p99 at or below rosbridge_server_rs's, on one stream",
    "image": "JSON >= 60 frames/s, CBOR >= 400 frames/s [rosbridge 14; 360]",
    "idle_cpu": "< 1 % of a core [rosbridge ~5 %]",
    "memory_stall": "bounded [rosbridge +400 MB in 6 s]",
    "tls": "reference only: the cost of wss:// against ws://",
    "workers_resume": "reference: the forwarding hop of a resume on the wrong worker",
    "params": "graph.params() warm < 50 ms, cold < 300 ms, a node without parameter "
              "services in the graph [2.03 s every call]",
    "links": "reference: a silent link noticed in seconds; frame age flat over a 2 Mbit/s link",
    "pointcloud": "4 MiB PointCloud2 at 10 Hz to 5 clients: all delivered; bridge CPU, RSS",
    "foxglove": "the Foxglove path at least as fast as rosbridge cbor-raw on the same bridge; "
                "10 Foxglove viewers of one camera: bridge CPU per frame",
    "relay_uplink": "robot uplink through a relay flat in viewers (<= 1.1x one viewer's); "
                    "straight to the bridge N times",
    "relay_service": "reference: service round trip through a relay against straight",
    "fanout": "<= 10 us of server CPU per delivered message to 100-200 viewers, bridge and "
              "relay; 100 viewers of a 10 Hz camera through one relay get every frame",
    "relay_imu": "200 viewers of a 100 Hz IMU over two relays: all delivered; latency, relay CPU",
    "relay_dead_link": "a dead robot link told to its relay's clients within the lease (3 s)",
    "relay_outage": "nothing lost in a robot-link outage within the window (300 messages: "
                    "30 s at 10 Hz); what is past it counted; robot memory bounded",
    "record": "camera 30 Hz + IMU 200 Hz for 60 s recorded without a loss; recorder CPU",
    "action_ros_server": "reference: goal round trip p50/p99, feedback msg/s at >= 99 %",
    "action_client_served": "reference: goal round trip p50/p99, feedback msg/s at >= 99 %",
    "fleet": "unwatched robot < 50 KB on a relay, no CPU; open p99 < 200 ms; back < 10 s "
             "after a router restart; churn leaves relay RSS within 5 %",
}

SCENARIOS: dict[str, Callable[[Ctx], Awaitable[dict[str, Any]]]] = {
    "rclpy_ceiling": rclpy_ceiling,
    "idle_cpu": idle_cpu,
    "ros_to_client": ros_to_client,
    "ros_to_client_raw": lambda ctx: ros_to_client(ctx, "cbor-raw"),
    "client_to_ros": client_to_ros,
    "service": service,
    "client_service": client_service,
    "latency": latency,
    "latency_side_by_side": latency_side_by_side,
    "image": image,
    "memory_stall": memory_stall,
    "tls": lambda ctx: tls_scenario(ctx, ros_to_client, service, image),
    "workers_resume": workers_resume,
    "params": params_scenario,
    "links": links,
    "record": record,
    "pointcloud": pointcloud,
    "foxglove": foxglove,
    "relay_uplink": relay_uplink,
    "relay_service": relay_service,
    "relay_imu": relay_imu,
    "fanout": fanout,
    "relay_dead_link": relay_dead_link,
    "relay_outage": relay_outage,
    "action_ros_server": action_ros_server,
    "action_client_served": action_client_served,
    "fleet": fleet,
}


def _headline(name: str, r: dict[str, Any]) -> Any:
    if "error" in r:
        return "error"
    if name == "rclpy_ceiling":
        return {"publish_rate": r["max"]["publish_rate"], "receive_rate": r["max"]["receive_rate"],
                "image_fps": r["image_640x480"]["frames_per_s"]}
    if name in ("ros_to_client", "ros_to_client_raw", "client_to_ros"):
        return r["best_rate_99pct"]
    if name in ("service", "client_service"):
        return {"p50_ms": r["p50_ms"], "p99_ms": r["p99_ms"], "calls_per_s": r["calls_per_s"]}
    if name == "latency":
        return {"p50_ms": r["p50_ms"], "p99_ms": r["p99_ms"]}
    if name == "latency_side_by_side":
        return {k: {"p50_ms": v["p50_ms"], "p99_ms": v["p99_ms"]}
                for k, v in r.items() if isinstance(v, dict) and "p50_ms" in v}
    if name == "image":
        return {k: r[k]["frames_per_s"] for k in ("json", "cbor", "cbor-raw") if k in r} | {
            "ros_ceiling": r["ros_ceiling"]["frames_per_s"]}
    if name == "idle_cpu":
        return r["connected_pct_of_core"]
    if name == "memory_stall":
        return {k: r[k] for k in ("rss_start_mb", "rss_peak_mb", "rss_end_mb")}
    if name.startswith("action_"):
        return {"p50_ms": r["round_trip"]["p50_ms"], "p99_ms": r["round_trip"]["p99_ms"],
                "feedback_rate_99pct": r["feedback_best_rate_99pct"]}
    if name == "pointcloud":
        return {c: {"all_delivered": r[c]["all_delivered"], "cpu_pct": r[c]["bridge_cpu_pct"],
                    "rss_peak_mb": r[c]["bridge_rss_mb"]["peak"]} for c in ("cbor", "cbor-raw")}
    if name == "foxglove":
        return {part: {path: r[part][path][key] for path in ("foxglove", "cbor-raw")}
                for part, key in (("image", "frames_per_s"), ("small", "best_rate_99pct"),
                                  ("viewers", "bridge_cpu_ms_per_published_frame"))}
    if name == "relay_uplink":
        return {way: {r["viewers"]: r["x_one_viewer"] for r in r[way]} for way in ("relay", "direct")}
    if name == "relay_service":
        return r
    if name == "fanout":
        return {part: [(s["viewers"], s["delivered_fraction"], s["server_cpu_us_per_message"])
                       for s in (r[part] if isinstance(r[part], list) else [r[part]])]
                for part in ("bridge", "relay", "camera_relay")}
    if name == "relay_dead_link":
        return {k: v["noticed_max_s"] for k, v in r.items() if k.startswith("lease_")}
    if name == "relay_outage":
        return {f"{o['outage_s']:g}s": {"lost": o["lost"], "recover_s": o["recover_s"]}
                for o in r["outages"]}
    if name == "relay_imu":
        return {k: r[k] for k in ("delivered_fraction", "latency_p50_ms", "latency_p99_ms",
                                  "relay_cpu_us_per_message")}
    if name == "record":
        return {"recorded_pct": {t: v["recorded_pct"] for t, v in r["camera_imu"]["topics"].items()},
                "recorder_cpu_pct": r["camera_imu"]["recorder_cpu_pct"],
                "best_camera_rate_99pct": r["best_camera_rate_99pct"]}
    if name == "params":
        return {k: r[k] for k in ("cold_ms", "warm_median_ms")}
    if name == "workers_resume":
        return {scheme: {kind: r[scheme][kind]["p50_ms"] for kind in ("direct", "forwarded")}
                for scheme in ("ws", "wss")}
    if name == "tls":
        keys = ("ros_to_client_best_rate_99pct", "service_p50_ms", "image_cbor_frames_per_s")
        return {scheme: {k: r[scheme][k] for k in keys} for scheme in ("ws", "wss")}
    return None


def _code() -> dict[str, str]:
    """Whose client and bridge were measured: the checkout, and where the client came from."""
    import importlib.util

    spec = importlib.util.find_spec("roslibpy_lite")
    return {"root": str(CODE_ROOT), "python": sys.executable,
            "roslibpy_lite": str(spec.origin) if spec else "not found"}


async def run(names: list[str], ctx: Ctx) -> int:
    """Run the scenarios in order, printing one JSON object each and a summary."""
    summary: dict[str, Any] = {}
    failed = 0
    t_all = time.monotonic()
    for name in names:
        t0 = time.monotonic()
        try:
            result = await SCENARIOS[name](ctx)
        except Exception as exc:  # report and go on with the next scenario
            result = {"error": f"{type(exc).__name__}: {exc}"}
            failed += 1
        result = {"scenario": name, "target": TARGETS[name], **result,
                  "wall_s": round(time.monotonic() - t0, 1)}
        print(json.dumps(result), flush=True)
        summary[name] = _headline(name, result)
    print(json.dumps({
        "summary": summary,
        "duration_per_step_s": ctx.duration,
        "quick": ctx.quick,
        "wall_s": round(time.monotonic() - t_all, 1),
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version()},
        "code": _code(),
    }), flush=True)
    return 1 if failed else 0


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The command line."""
    p = argparse.ArgumentParser(prog="python -m bench",
                                description="End-to-end benchmarks of the bridge (JSON output).")
    p.add_argument("--scenario", nargs="+", default=["all"],
                   help=f"all (the default), or some of: {', '.join(SCENARIOS)}")
    p.add_argument("--duration", type=float, default=None,
                   help="seconds per measurement step (default 3, --quick 1.5)")
    p.add_argument("--quick", action="store_true", help="short steps, fewer rates (~2 minutes)")
    p.add_argument("--profile", action="store_true",
                   help="py-spy the bridge during ros_to_client, image, service and "
                        "client_service, the recorder during record")
    p.add_argument("--domain", type=int, default=int(os.environ.get("BENCH_ROS_DOMAIN_ID", "42")),
                   help="ROS_DOMAIN_ID for the bridge and ROS side (default $BENCH_ROS_DOMAIN_ID, else 42)")
    p.add_argument("--ros-executor", choices=("events", "single"), default="events",
                   help="rclpy executor of the ROS-side processes (default events: much faster)")
    p.add_argument("--bridge-root", default=None,
                   help="run the bridge from another checkout (A/B comparisons); default: this one")
    p.add_argument("--peer", choices=("ours", "rs"), default="ours",
                   help="the server under test: ours, or rosbridge_server_rs (Rust; "
                   "../shared/peers/rosbridge_server_rs.sh, no rosapi) for side-by-side figures "
                   "(default ours)")
    p.add_argument("--compare", metavar="REV", default=None,
                   help="A/B: this tree against git revision REV, alternating, one table "
                   "(bench/README.md); the scenarios default to the compare set")
    p.add_argument("--repeat", type=int, default=3,
                   help="--compare: rounds of each side (default 3)")
    p.add_argument("--compare-json", metavar="PATH", default=None,
                   help="--compare: where to write the table as JSON (default: the cache folder)")
    p.add_argument("--bridge-arg", action="append", default=[],
                   help="extra bridge command-line argument (repeatable), e.g. --bridge-arg=--event-loop=asyncio")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Entry point."""
    args = parse_args(argv)
    if args.compare and args.scenario == ["all"]:
        names = list(COMPARE_SCENARIOS)
    else:
        names = list(SCENARIOS) if "all" in args.scenario else args.scenario
    unknown = [n for n in names if n not in SCENARIOS]
    if unknown:
        print(f"unknown scenario(s): {', '.join(unknown)}; known: {', '.join(SCENARIOS)}",
              file=sys.stderr)
        return 2
    if args.compare:
        return compare(args, names)
    duration = args.duration if args.duration is not None else (1.5 if args.quick else 3.0)
    ctx = Ctx(duration=duration, quick=args.quick, domain=args.domain, profile=args.profile,
              ros_executor=args.ros_executor, bridge_args=list(args.bridge_arg),
              bridge_root=args.bridge_root, peer=args.peer)
    return asyncio.run(run(names, ctx))


if __name__ == "__main__":
    sys.exit(main())
