"""Message encodings that need no ROS: shared by the rclpy bridge and the relay.

- :mod:`.cdr_json`: a message's JSON text straight from its CDR bytes (``msgs.cdr``);
- :mod:`.publish`: the ``publish`` op around an encoded message, as JSON text, CBOR and
  ``cbor-raw``.

Nothing here imports rclpy (``tests/core/test_ros_boundary.py`` keeps it so), so a relay
on a machine without ROS encodes with the same code as the bridge.
"""
