"""Record and replay MCAP files from any machine, without ROS (``pip install roslibpy-lite[mcap]``).

:class:`Recorder` subscribes with ``raw=True`` (the bridge sends ``cbor-raw``: it converts
nothing and this side decodes nothing) and writes what rosbag2 writes: one ``ros2msg``
schema per type with the full definition text from the bridge, ``cdr`` messages, log time
= when this client received the message, publish time = the bridge's stamp, and each
channel's ``offered_qos_profiles`` (the publishers' QoS, which our bridge reports), so
that players re-latch latched topics. :func:`read`
and :func:`info` read our files and those of rosbag2 and other tools (typed messages
through :mod:`msgs.dynamic`, from the file's own schemas); :func:`play` publishes a file
through the bridge with its recorded timing. All of it works on :class:`~roslibpy_lite.Client`
and :class:`~roslibpy_lite.MockRos` alike::

    async with roslibpy_lite.connect(url) as ros:
        async with Recorder(ros, "run.mcap", topics=["/imu", "/camera/*"]) as rec:
            await asyncio.sleep(60)
        print(rec.stats)
"""

from __future__ import annotations

from .player import PlayStats, play
from .reader import BagInfo, BagMessage, TopicInfo, info, read
from .recorder import Recorder, RecordStats, empty_recording

__all__ = [
    "BagInfo",
    "BagMessage",
    "PlayStats",
    "RecordStats",
    "Recorder",
    "TopicInfo",
    "empty_recording",
    "info",
    "play",
    "read",
]
