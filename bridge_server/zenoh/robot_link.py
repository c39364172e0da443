"""The robot's link options: what a robot's Zenoh session adds to :class:`.ZenohOptions`.

Zenoh sends from its highest-priority queue first (:mod:`.priority`), but what it has
written to the TCP socket is sent in order: a camera's frames fill the kernel's send buffer
(Linux lets it grow to 4 MiB, two seconds of a 2 MB/s uplink) and a counter's message
written after them waits for all of it, whatever its priority. So the robot's link keeps
that buffer small (:data:`DEFAULT_SNDBUF`, the robot's ``--zenoh-sndbuf``) and its batches
small (:data:`BATCH`): Zenoh's queues hold the rest, where priorities apply. Measured through
``bench/linkproxy.py`` at 50 ms RTT and 2 MB/s with a 640x480 camera at 10 Hz beside a 10 Hz
counter and a 100 Hz IMU (``tests/relay/test_link_priority.py``): the counter's gap p99 was
2.3 s before, 0.7 s with priorities and this buffer at 256 KiB, 0.14 s with 64 KiB and
16 KiB batches (0.9 s with every topic at one priority).

A small buffer bounds what is in flight unacknowledged, so it bounds throughput on a long
link to about ``sndbuf / RTT`` (Linux doubles the number for its bookkeeping): 64 KiB at
50 ms carries some 2.6 MB/s. A robot streaming more than that over a long link raises it.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING

from bridge_server.zenoh.link import ZenohOptions, options_from_args
from rosbridge_core.interfaces import BridgeError

if TYPE_CHECKING:
    import zenoh

__all__ = ["DEFAULT_SNDBUF", "RobotOptions", "add_arguments", "options_refusal",
           "robot_options"]

DEFAULT_SNDBUF = 64 * 1024
"""Bytes of the kernel's send buffer of the robot's link (``--zenoh-sndbuf``)."""

BATCH = 16 * 1024
"""Bytes of one Zenoh batch on the robot's link (Zenoh's default is 64 KiB): a small
message of a higher priority waits for the batch on the wire, a quarter of what it would."""

BULK_QUEUE = 16
"""Batches Zenoh queues for ``data_low`` (big messages) on the robot's link."""


@dataclass
class RobotOptions(ZenohOptions):
    """A robot's :class:`.ZenohOptions`, with its link's send buffer."""

    sndbuf: int = DEFAULT_SNDBUF
    """The kernel's send buffer of each of the robot's links, bytes (0: the system's)."""

    def config(self) -> zenoh.Config:
        """The Zenoh configuration, the send buffer set on tcp/ and tls/ links."""
        conf = super().config()
        if self.sndbuf < 0:
            raise BridgeError(f"--zenoh-sndbuf {self.sndbuf}: expected 0 or more bytes")
        if self.sndbuf:
            for proto in ("tcp", "tls"):
                conf.insert_json5(f"transport/link/{proto}/so_sndbuf", json.dumps(self.sndbuf))
        # A big message is put whole by its own thread, blocking there while the link is
        # full (.bulk): its priority's queue holds 16 batches, and a full queue closes the
        # link only after a minute (Zenoh's 5 s would close a slow uplink that takes longer
        # to carry one batch; a dead one ends with its lease).
        conf.insert_json5("transport/link/tx/batch_size", json.dumps(BATCH))
        queue = "transport/link/tx/queue"
        conf.insert_json5(f"{queue}/size/data_low", json.dumps(BULK_QUEUE))
        conf.insert_json5(f"{queue}/congestion_control/block/wait_before_close",
                          json.dumps(60_000_000))
        return conf


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The robot's own link options (beside :func:`.link.add_arguments`)."""
    p.add_argument("--zenoh-sndbuf", type=int, default=DEFAULT_SNDBUF, metavar="BYTES",
                   help="the kernel's send buffer of the robot's Zenoh link (default "
                   "%(default)s; 0: the system's, up to 4 MiB): what is written to the link "
                   "is sent in order whatever its priority, so a small buffer lets small "
                   "messages overtake camera frames; it bounds throughput to about BYTES per "
                   "round trip")


def robot_options(args: argparse.Namespace) -> RobotOptions:
    """The robot's link options from its command line."""
    base = options_from_args(args)
    return RobotOptions(**{f.name: getattr(base, f.name) for f in fields(base)},
                        sndbuf=args.zenoh_sndbuf)


def options_refusal(options: ZenohOptions) -> str | None:
    """Why a robot must not start with ``options`` (a tls/ endpoint without
    ``--zenoh-tls-ca``, a certificate without its key...): it exits, as a relay does,
    instead of running with no uplink (``None``: they may)."""
    try:
        options.config()
    except BridgeError as exc:
        return str(exc)
    return None
