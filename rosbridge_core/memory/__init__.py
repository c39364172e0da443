"""A whole ROS graph in memory (:mod:`.graph`): the :class:`~rosbridge_core.graph.Graph` port
with no rclpy, no Zenoh and no sockets, for session tests and MockRos."""
