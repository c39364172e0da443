"""The ROS side of the action benchmarks, run in its own process (JSON event lines on stdout).

Sub-commands (all on ``test_msgs/action/Fibonacci``):

``serve``     an rclpy action server. A goal with ``order`` 0 succeeds at once
              (round trips); ``order`` R > 0 streams feedback at R msg/s for
              ``--duration`` s (``sequence: [seq]``), then succeeds with
              ``sequence: [count sent]``. Runs until stdin closes.
``call``      an rclpy action client: ``--goals`` sequential goals of order 0
              (after ``--warmup`` more), reporting round-trip quantiles in ms.
``feedback``  an rclpy action client: one goal of ``order`` ``--rate``; counts the
              distinct feedback sequence numbers until the result, which says
              how many were sent.

Examples::

    python bench/ros_actions_side.py serve --action /a --duration 2
    python bench/ros_actions_side.py call --action /a --goals 500
    python bench/ros_actions_side.py feedback --action /a --rate 2000
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import threading
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

from bench.ros_side import _quantiles, emit


def _node(name: str) -> tuple[Any, Any]:
    import rclpy
    from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor

    rclpy.init()
    node = rclpy.create_node(f"{name}_{os.getpid()}")
    # the server's execute callbacks block a thread each; a client's single thread keeps
    # rclpy's action client (not thread safe) to one thread
    executor: Any = (
        MultiThreadedExecutor(num_threads=4) if name.endswith("server")
        else SingleThreadedExecutor()
    )
    executor.add_node(node)
    if not name.endswith("server"):
        threading.Thread(target=executor.spin, daemon=True).start()
    return node, executor


def _deep() -> dict[str, Any]:
    return {"goal_service_qos_profile": _qos_deep(), "result_service_qos_profile": _qos_deep()}


def cmd_serve(args: argparse.Namespace) -> int:
    """Serve Fibonacci goals (see the module docstring) until stdin closes."""
    from test_msgs.action import Fibonacci

    action: Any = importlib.import_module("rclpy.action")
    groups: Any = importlib.import_module("rclpy.callback_groups")
    node, executor = _node("bench_action_server")

    def execute(handle: Any) -> Any:
        rate = handle.request.order
        sent = 0
        if rate > 0:
            n = int(rate * args.duration)
            t0 = time.monotonic()
            for seq in range(n):
                due = t0 + seq / rate
                ahead = due - time.monotonic()
                if ahead > 0.001:
                    time.sleep(ahead)
                handle.publish_feedback(Fibonacci.Feedback(sequence=[seq]))
            sent = n
        handle.succeed()
        return Fibonacci.Result(sequence=[sent])

    action.ActionServer(node, Fibonacci, args.action, execute,
                        callback_group=groups.ReentrantCallbackGroup(),
                        feedback_pub_qos_profile=_qos_deep(), **_deep())
    threading.Thread(target=_exit_on_eof, daemon=True).start()
    emit("ready")
    executor.spin()
    return 0


def _exit_on_eof() -> None:
    sys.stdin.read()  # until the benchmark closes stdin
    os._exit(0)


def _qos_deep() -> Any:
    from rclpy.qos import QoSProfile

    return QoSProfile(depth=1000)  # type: ignore[no-untyped-call]


def _client(node: Any, executor: Any, name: str) -> Any:
    from test_msgs.action import Fibonacci

    action: Any = importlib.import_module("rclpy.action")
    client = action.ActionClient(node, Fibonacci, name, feedback_sub_qos_profile=_qos_deep(),
                                 **_deep())
    deadline = time.monotonic() + 20
    while not client.server_is_ready():
        if time.monotonic() > deadline:
            emit("error", error=f"no action server {name}")
            sys.exit(1)
        time.sleep(0.01)
    emit("matched")
    return client


def _run_goal(client: Any, executor: Any, order: int, feedback: Any = None,
              timeout: float = 60.0) -> Any:
    """One goal; rclpy's action client is not thread safe, so it is sent from the executor."""
    from test_msgs.action import Fibonacci

    done = threading.Event()
    box: dict[str, Any] = {}

    def on_result(future: Any) -> None:
        box["result"] = future.result()
        done.set()

    def on_goal(future: Any) -> None:
        handle = future.result()
        if not handle.accepted:
            done.set()
            return
        handle.get_result_async().add_done_callback(on_result)

    def send() -> None:
        future = client.send_goal_async(Fibonacci.Goal(order=order), feedback_callback=feedback)
        future.add_done_callback(on_goal)

    executor.create_task(send)
    if not done.wait(timeout):
        raise TimeoutError("no result")
    return box.get("result")


def cmd_call(args: argparse.Namespace) -> int:
    """Sequential goals of order 0: round trip quantiles (goal sent to result received)."""
    node, executor = _node("bench_action_caller")
    client = _client(node, executor, args.action)
    for _ in range(args.warmup):
        _run_goal(client, executor, 0)
    lat: list[float] = []
    failed = 0
    for _ in range(args.goals):
        t = time.perf_counter_ns()
        result = _run_goal(client, executor, 0)
        lat.append((time.perf_counter_ns() - t) / 1e6)
        failed += result is None or result.status != 4
    emit("done", goals=args.goals, failed=failed, latency_ms=_quantiles(lat))
    return 0


def cmd_feedback(args: argparse.Namespace) -> int:
    """One goal of order ``--rate``: how much of its feedback stream arrives."""
    node, executor = _node("bench_action_feedback")
    client = _client(node, executor, args.action)
    seen: set[int] = set()
    times: list[float] = []

    def on_feedback(msg: Any) -> None:
        seen.update(msg.feedback.sequence)
        times.append(time.monotonic())

    for _ in range(args.warmup):  # discovery of this new node settles on both sides
        _run_goal(client, executor, 0)
    t0 = time.monotonic()
    result = _run_goal(client, executor, args.rate, on_feedback)
    t_result = time.monotonic() - t0
    sent = result.result.sequence[0] if result is not None and result.result.sequence else 0
    span = times[-1] - times[0] if len(times) > 1 else 0.0
    emit("done", sent=int(sent), unique=len(seen), rate=(len(times) - 1) / span if span else 0.0,
         status=None if result is None else result.status, result_s=round(t_result, 3),
         first_feedback_s=round(times[0] - t0, 3) if times else None,
         last_feedback_s=round(times[-1] - t0, 3) if times else None)
    return 0


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The command line."""
    p = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    for name in ("serve", "call", "feedback"):
        s = sub.add_parser(name)
        s.add_argument("--action", required=True)
        s.add_argument("--duration", type=float, default=2.0)
        s.add_argument("--executor", default="multi", help="ignored (harness compatibility)")
        if name != "serve":
            s.add_argument("--warmup", type=int, default=20 if name == "call" else 5)
        if name == "call":
            s.add_argument("--goals", type=int, default=500)
        if name == "feedback":
            s.add_argument("--rate", type=int, required=True)
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Entry point."""
    args = parse_args(argv)
    handler = {"serve": cmd_serve, "call": cmd_call, "feedback": cmd_feedback}[args.cmd]
    code = handler(args)
    os._exit(code)  # skip rclpy's slow teardown of the spinning executor


if __name__ == "__main__":
    sys.exit(main())
