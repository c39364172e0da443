"""The ROS side of a benchmark scenario, run in its own process (so figures measure the bridge).

Sub-commands (each prints JSON lines on stdout: ``{"event": ...}``):

``publish``    publish numbered messages in a tight timed loop
               (``--kind string|stamp|image|imu``, ``--rate`` msg/s, 0 = as fast as it can;
               several ``--topic``: each message goes to the next topic in turn)
``subscribe``  count numbered messages on a topic (std_msgs/String, raw CDR, no deserialising)
``serve``      serve ``std_srvs/srv/SetBool`` (answers ``success = data``) until stdin closes
``call``       call a ``std_srvs/srv/SetBool`` service: round trips of sequential calls, then
               calls/s with ``--in-flight`` outstanding

Examples::

    python bench/ros_side.py publish --topic /x --rate 8000 --duration 3
    python bench/ros_side.py subscribe --topic /x --idle 1.0 --duration 20
    python bench/ros_side.py serve --service /svc
    python bench/ros_side.py call --service /svc --calls 500 --in-flight 16 --duration 3

Message formats: ``string`` data is the decimal sequence number; ``stamp`` data
is ``"<seq> <time.monotonic_ns()>"`` taken just before publishing; ``image`` is a
640x480 rgb8 ``sensor_msgs/Image`` whose ``header.frame_id`` is the sequence
number and the send time; ``imu`` (``sensor_msgs/Imu``) and ``cloud`` (a 4 MiB
``sensor_msgs/PointCloud2`` of random x, y, z, intensity) are numbered the same way.
Every run waits for ``--wait-subs`` matched subscriptions first and reports
``{"event": "matched"}`` when they are there.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import threading
import time
from typing import Any

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")


def emit(event: str, **fields: Any) -> None:
    """Print one JSON event line and flush."""
    print(json.dumps({"event": event, **fields}), flush=True)


def _qos(args: argparse.Namespace) -> Any:
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(  # type: ignore[no-untyped-call]
        history=HistoryPolicy.KEEP_LAST,
        depth=args.depth,
        reliability=(
            ReliabilityPolicy.BEST_EFFORT if args.best_effort else ReliabilityPolicy.RELIABLE
        ),
        durability=(
            DurabilityPolicy.TRANSIENT_LOCAL if args.latched else DurabilityPolicy.VOLATILE
        ),
    )


def _wait(cond: Any, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.005)
    return True


def cmd_publish(args: argparse.Namespace) -> int:
    """Publish ``--count`` messages or for ``--duration`` seconds at ``--rate`` msg/s."""
    import rclpy

    rclpy.init()
    node = rclpy.create_node(f"bench_pub_{os.getpid()}")
    if args.kind == "image":
        from sensor_msgs.msg import Image

        msg: Any = Image()
        msg.height, msg.width, msg.encoding, msg.step = 480, 640, "rgb8", 640 * 3
        size = 640 * 480 * 3
        msg.data = os.urandom(size) if args.noise else bytes(range(256)) * (size // 256)
        msg_type: Any = Image
    elif args.kind == "cloud":
        from sensor_msgs.msg import PointCloud2, PointField

        msg = PointCloud2(height=1, width=4 * 1024 * 1024 // 16, point_step=16,
                          is_dense=True)
        msg.fields = [PointField(name=n, offset=4 * k, datatype=PointField.FLOAT32, count=1)
                      for k, n in enumerate(("x", "y", "z", "intensity"))]
        msg.row_step = msg.width * msg.point_step
        msg.data = os.urandom(msg.row_step)
        msg_type = PointCloud2
    elif args.kind == "imu":
        from sensor_msgs.msg import Imu

        msg = Imu()
        msg.linear_acceleration.z = 9.81
        msg_type = Imu
    else:
        from std_msgs.msg import String

        msg = String()
        msg_type = String
    # several --topic: the messages go to each in turn (side-by-side latency runs)
    pubs = [node.create_publisher(msg_type, topic, _qos(args)) for topic in args.topic]
    if args.wait_subs and not _wait(
        lambda: all(p.get_subscription_count() >= args.wait_subs for p in pubs),
        args.match_timeout,
    ):
        emit("error", error=f"no {args.wait_subs} subscriber(s) on {', '.join(args.topic)}")
        node.destroy_node()  # type: ignore[no-untyped-call]
        rclpy.shutdown()
        return 1
    emit("matched", subscribers=sum(p.get_subscription_count() for p in pubs))
    if args.settle > 0:
        time.sleep(args.settle)
    rate = args.rate
    period_ns = int(1e9 / rate) if rate > 0 else 0
    count = args.count
    kind = args.kind
    stop_ns = time.monotonic_ns() + int(args.duration * 1e9)
    t0 = time.monotonic_ns()
    i = 0
    publishes = [p.publish for p in pubs]
    n_pubs = len(pubs)
    mono = time.monotonic_ns
    while True:
        now = mono()
        if (count and i >= count) or (not count and now >= stop_ns):
            break
        if period_ns:
            due = t0 + i * period_ns
            if now < due:
                gap = due - now
                if gap > 300_000:
                    time.sleep((gap - 200_000) / 1e9)
                continue
        if kind == "string":
            msg.data = str(i)
        elif kind == "stamp":
            msg.data = f"{i} {mono()}"
        else:  # image, imu, cloud: sequence and send time (monotonic ns)
            msg.header.frame_id = f"{i} {mono()}"
        publishes[i % n_pubs](msg)
        i += 1
    elapsed = (mono() - t0) / 1e9
    emit("done", sent=i, elapsed=elapsed, rate=i / elapsed if elapsed else 0.0,
         t_end=time.monotonic())
    if args.linger > 0:  # keep the writer alive so reliable readers can catch up
        time.sleep(args.linger)
    node.destroy_node()  # type: ignore[no-untyped-call]
    rclpy.shutdown()
    return 0


def cmd_subscribe(args: argparse.Namespace) -> int:
    """Count numbered std_msgs/String messages (raw CDR, parsed by hand)."""
    import rclpy
    from std_msgs.msg import String

    rclpy.init()
    node = rclpy.create_node(f"bench_sub_{os.getpid()}")
    state = {"n": 0, "first": -1, "last": -1, "t_first": 0.0, "t_last": 0.0, "seen": 0}
    in_order_at: list[float] = []  # image frames numbered above all before them: arrival times
    seen = bytearray(args.expect) if args.expect else None
    stamped = args.stamped
    latencies: list[float] = []

    def on_image(data: bytes) -> None:
        # raw CDR, nothing deserialised but the sequence number in header.frame_id (after the
        # encapsulation and the stamp): frames/s, and how many came in order, the ROS side carries
        now = time.monotonic()
        seq = int(data[16:16 + int.from_bytes(data[12:16], "little") - 1].split(b" ", 1)[0])
        if state["n"] == 0:
            state["t_first"] = now
            state["first"] = seq
        state["n"] += 1
        state["t_last"] = now
        if seq > state["last"]:
            in_order_at.append(now)
            state["last"] = seq

    def on_raw(data: bytes) -> None:
        # CDR: 4-byte encapsulation header, uint32 length (incl. NUL), chars, NUL.
        n = int.from_bytes(data[4:8], "little")
        text = data[8 : 8 + n - 1]
        if stamped:  # "<seq> <monotonic_ns>"
            recv_ns = time.monotonic_ns()
            head, _, stamp = text.partition(b" ")
            seq = int(head)
            if seq >= 20:  # skip warm-up
                latencies.append((recv_ns - int(stamp)) / 1e6)
        else:
            seq = int(text)
        now = time.monotonic()
        if state["n"] == 0:
            state["first"] = seq
            state["t_first"] = now
        state["n"] += 1
        state["last"] = seq
        state["t_last"] = now
        if seen is not None and 0 <= seq < len(seen) and not seen[seq]:
            seen[seq] = 1
            state["seen"] += 1

    if args.kind == "image":
        from sensor_msgs.msg import Image

        sub = node.create_subscription(Image, args.topic, on_image, _qos(args), raw=True)
    else:
        sub = node.create_subscription(String, args.topic, on_raw, _qos(args), raw=True)
    executor = _executor(args)
    executor.add_node(node)
    spin_once = executor.spin_once
    deadline = time.monotonic() + args.match_timeout
    while sub.get_publisher_count() < args.wait_pubs and time.monotonic() < deadline:
        spin_once(timeout_sec=0.01)
    if sub.get_publisher_count() < args.wait_pubs:
        emit("error", error=f"no publisher on {args.topic}")
    else:
        emit("matched", publishers=sub.get_publisher_count())
    # spin in this thread (rclpy's EventsExecutor hears nothing when spun in another thread)
    deadline = time.monotonic() + args.duration
    while True:
        spin_once(timeout_sec=0.05)
        now = time.monotonic()
        if now > deadline:
            break
        if state["n"] and now - float(state["t_last"]) > args.idle:
            break
        if args.expect and state["seen"] >= args.expect:
            break
    span = float(state["t_last"]) - float(state["t_first"])
    emit(
        "done",
        received=state["n"],
        unique=state["seen"] if seen is not None else None,
        in_order_at=[round(t, 4) for t in in_order_at] if args.kind == "image" else None,
        first=state["first"],
        last=state["last"],
        span=span,
        rate=(int(state["n"]) - 1) / span if span > 0 else 0.0,
        latency_ms=_quantiles(latencies) if stamped else None,
    )
    executor.shutdown(timeout_sec=1.0)
    node.destroy_node()  # type: ignore[no-untyped-call]
    rclpy.shutdown()
    return 0


def _quantiles(values: list[float]) -> dict[str, float] | None:
    if not values:
        return None
    v = sorted(values)

    def q(p: float) -> float:
        return round(v[min(len(v) - 1, round(p * (len(v) - 1)))], 3)

    return {"n": len(v), "p50": q(0.5), "p90": q(0.9), "p99": q(0.99), "max": round(v[-1], 3)}


def cmd_serve(args: argparse.Namespace) -> int:
    """Serve std_srvs/srv/SetBool until stdin closes (or ``--duration`` passes)."""
    import rclpy
    from std_srvs.srv import SetBool

    rclpy.init()
    node = rclpy.create_node(f"bench_srv_{os.getpid()}")
    calls = [0]

    def handle(request: Any, response: Any) -> Any:
        calls[0] += 1
        response.success = bool(request.data)
        response.message = "ok"
        return response

    # the default service QoS keeps only 10 requests: more in flight would be lost
    node.create_service(SetBool, args.service, handle, qos_profile=_qos(args))
    executor = _executor(args)
    executor.add_node(node)
    emit("ready", service=args.service)
    stdin_closed = threading.Event()

    def watch_stdin() -> None:
        sys.stdin.read()
        stdin_closed.set()

    threading.Thread(target=watch_stdin, daemon=True).start()
    deadline = time.monotonic() + args.duration
    while not stdin_closed.is_set() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    emit("done", calls=calls[0])
    executor.shutdown(timeout_sec=1.0)
    node.destroy_node()  # type: ignore[no-untyped-call]
    rclpy.shutdown()
    return 0


def cmd_call(args: argparse.Namespace) -> int:
    """Call std_srvs/srv/SetBool: ``--calls`` one at a time (round trips in ms), then as many
    as it can with ``--in-flight`` outstanding for ``--duration`` seconds (calls/s)."""
    import rclpy
    from std_srvs.srv import SetBool

    rclpy.init()
    node = rclpy.create_node(f"bench_caller_{os.getpid()}")
    client = node.create_client(SetBool, args.service, qos_profile=_qos(args))
    executor = _executor(args)
    executor.add_node(node)
    spin_once = executor.spin_once
    deadline = time.monotonic() + args.match_timeout
    while not client.service_is_ready() and time.monotonic() < deadline:
        spin_once(timeout_sec=0.01)
    if not client.service_is_ready():
        emit("error", error=f"no server for {args.service}")
        return 1
    emit("matched")
    request = SetBool.Request(data=True)
    failed = 0

    def settle(future: Any) -> None:
        nonlocal failed
        result = future.result()
        failed += result is None or not result.success

    def call_and_wait() -> None:
        future: Any = client.call_async(request)
        stop = time.monotonic() + args.match_timeout
        while not future.done():
            if time.monotonic() > stop:
                raise TimeoutError(f"no answer from {args.service} in {args.match_timeout} s")
            spin_once(timeout_sec=0.05)
        settle(future)

    for _ in range(args.warmup):
        call_and_wait()
    latencies: list[float] = []
    for _ in range(args.calls):
        t = time.perf_counter_ns()
        call_and_wait()
        latencies.append((time.perf_counter_ns() - t) / 1e6)
    done = 0
    pending: set[Any] = set()
    t0 = time.monotonic()
    stop_at = t0 + args.duration
    while pending or time.monotonic() < stop_at:
        while len(pending) < args.in_flight and time.monotonic() < stop_at:
            pending.add(client.call_async(request))
        spin_once(timeout_sec=0.05)
        for future in [f for f in pending if f.done()]:
            pending.discard(future)
            settle(future)
            done += 1
        if time.monotonic() > stop_at + args.match_timeout:
            break  # answers lost: say so below
    elapsed = time.monotonic() - t0
    emit("done", latency_ms=_quantiles(latencies), calls=args.calls, failed=failed,
         in_flight=args.in_flight, calls_per_s=done / elapsed, unanswered=len(pending))
    executor.shutdown(timeout_sec=1.0)
    node.destroy_node()  # type: ignore[no-untyped-call]
    rclpy.shutdown()
    return 0


def _executor(args: argparse.Namespace) -> Any:
    """The executor ``--executor`` names."""
    if args.executor == "events":
        from rclpy.experimental.events_executor import EventsExecutor

        return EventsExecutor()
    from rclpy.executors import SingleThreadedExecutor

    return SingleThreadedExecutor()


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The command line."""
    p = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    for name in ("publish", "subscribe", "serve", "call"):
        s = sub.add_parser(name)
        s.add_argument("--duration", type=float, default=3.0)
        s.add_argument("--match-timeout", type=float, default=15.0)
        s.add_argument("--depth", type=int, default=1000)
        s.add_argument("--best-effort", action="store_true")
        s.add_argument("--latched", action="store_true")
        s.add_argument("--executor", choices=("single", "events"), default="events")
        if name == "publish":
            s.add_argument("--topic", required=True, action="append",
                           help="repeatable: messages go to each topic in turn")
            s.add_argument("--kind", choices=("string", "stamp", "image", "imu", "cloud"),
                           default="string")
            s.add_argument("--rate", type=float, default=0.0, help="msg/s, 0: as fast as possible")
            s.add_argument("--count", type=int, default=0, help="stop after N (0: use duration)")
            s.add_argument("--wait-subs", type=int, default=1)
            s.add_argument("--settle", type=float, default=0.0)
            s.add_argument("--linger", type=float, default=1.0)
            s.add_argument("--noise", action="store_true",
                           help="image pixels are random (as incompressible as a camera's)")
        elif name == "subscribe":
            s.add_argument("--topic", required=True)
            s.add_argument("--wait-pubs", type=int, default=1)
            s.add_argument("--idle", type=float, default=1.0)
            s.add_argument("--expect", type=int, default=0)
            s.add_argument("--kind", choices=("string", "image"), default="string")
            s.add_argument("--stamped", action="store_true",
                           help='data is "<seq> <monotonic_ns>": report one-way latency')
        else:
            s.add_argument("--service", required=True)
        if name == "call":
            s.add_argument("--calls", type=int, default=1000, help="sequential calls timed")
            s.add_argument("--warmup", type=int, default=50, help="sequential calls first")
            s.add_argument("--in-flight", type=int, default=16,
                           help="outstanding calls for --duration seconds (calls/s)")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Entry point."""
    args = parse_args(argv)
    handler = {"publish": cmd_publish, "subscribe": cmd_subscribe, "serve": cmd_serve,
               "call": cmd_call}[args.cmd]
    return handler(args)


if __name__ == "__main__":
    sys.exit(main())
