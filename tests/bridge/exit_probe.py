"""``python -m tests.bridge.exit_probe bridge|relay ARGS...``: run the bridge's or the relay's
own ``main`` as the program, with an rclpy executor thread that spends its time inside
``rcl_wait`` (1 ms waits) as the process ends.

Such a thread is what makes a Python program that ends by finalising the interpreter die of
SIGABRT (``terminate called without an active exception``, exit 134): CPython ends it with
``pthread_exit`` when it wakes and asks for the GIL, and the unwind through pybind11's frames
calls ``std::terminate``. A bridge's own executor thread, Fast DDS's or Zenoh's do the same
now and then (issue 43: 1 start refusal in 30); this one does it nearly every time, so the
exit-status tests see the mechanism at each run instead of once in many.
"""

from __future__ import annotations

import importlib
import sys
import threading

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions

PROGRAMS = {"bridge": "bridge_server.__main__", "relay": "bridge_server.zenoh.relay"}


def start_waiting_thread() -> None:
    """An rclpy node spun by a daemon thread in 1 ms waits (in its own context, no signal
    handlers: the program's own SIGINT and SIGTERM handling is untouched)."""
    context = Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("exit_probe", context=context, start_parameter_services=False)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)

    def spin() -> None:
        while True:
            executor.spin_once(timeout_sec=0.001)

    threading.Thread(target=spin, name="exit-probe-spin", daemon=True).start()


def main() -> None:
    """Start the thread, then run the program named by the first argument with the rest."""
    program, *argv = sys.argv[1:]
    start_waiting_thread()
    sys.argv = [program, *argv]
    sys.exit(importlib.import_module(PROGRAMS[program]).main())


if __name__ == "__main__":
    main()
