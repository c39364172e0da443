"""The ROS side of the bridge on rclpy: the only package that imports ROS (a test keeps it so).

- :mod:`.graph`: :class:`~.graph.RclpyGraph`, the :class:`~rosbridge_core.graph.Graph`
  the sessions hold;
- :mod:`.node`: the rclpy node, its executor thread and hand-offs, holding the parts below;
- :mod:`.topics`: shared subscriptions and publishers, and the messages they hand out;
- :mod:`.calls`: calling ROS services (cached clients, waiting for a matched server);
- :mod:`.served`: ROS services a client serves;
- :mod:`.qos`: the QoS profiles of the bridge's entities;
- :mod:`.reader`: what waits on the topics and wakes the event loop;
- :mod:`.actions`: action clients and servers on rclpy's C layer;
- :mod:`.introspection`: rosapi typedefs, interface definitions, node parameters;
- :mod:`.convert`: message conversion (rclpy objects to and from rosbridge JSON/CBOR;
  JSON straight from CDR bytes and the ``publish`` envelopes are
  :mod:`rosbridge_core.codec`'s, which needs no ROS);
- :mod:`.fields` and :mod:`.validate`: the converter's field model and its inbound
  validators;
- :mod:`.types`: type names resolved to rclpy classes.
"""
