"""The stock Foxglove WebSocket client (``@foxglove/ws-protocol`` from npm, unchanged) in Node
against our bridge on the rosbridge port, with rclpy on the ROS side.

The Node driver is ``tests/peers/node/foxglove_peer.mjs``; it decodes and encodes CDR with
``@foxglove/rosmsg2-serialization`` from the schemas the bridge advertises, so a message
that arrives equal to what rclpy published shows that the channel, its schema and the raw
bytes all agree.
"""
