"""What a stock client must be able to do through our bridge, with rclpy on the other side.

Each function is one scenario, written once and run against every stock client
(``test_stock.py``, parametrized by the client). ``peer`` is a started
:class:`~tests.peers.peer.PeerProcess`; ``node`` is the test's rclpy node.
Waiting on the ROS graph (a publisher or subscriber being discovered) polls
with a deadline, because discovery has no event; everything else waits on
events: a queue, a reply line, a future's callback.

The scenarios live in one module per kind: :mod:`.topics`, :mod:`.services`, :mod:`.rosapi`,
:mod:`.cbor`, :mod:`.actions` and :mod:`.clients` (between two stock clients, and the bridge
restarting under one); :mod:`.support` holds the times and the waiting they share. Every
name is re-exported here, so ``from tests.peers import scenarios`` and
``from tests.peers.scenarios import X`` work as before.
"""

from __future__ import annotations

from tests.peers.scenarios.actions import (
    cancel_goal,
    send_goal,
    serve_action,
    serve_action_canceled,
)
from tests.peers.scenarios.cbor import (
    CBOR_ARRAYS,
    mixed_encodings,
    subscribe_cbor,
    subscribe_cbor_bytes,
    subscribe_cbor_raw,
    subscribe_cbor_typed_array,
)
from tests.peers.scenarios.clients import (
    client_to_client_action,
    client_to_client_failure,
    client_to_client_service,
    client_to_client_topic,
    latched_to_second_client,
    reconnect_after_bridge_restart,
)
from tests.peers.scenarios.rosapi import (
    FOXGLOVE_PARAMETERS,
    declare_foxglove_parameters,
    get_action_servers,
    get_nodes,
    get_publishers,
    get_services,
    get_time,
    get_topic_type,
    get_topics,
    message_details,
    params,
    service_details,
    topics_and_raw_types,
)
from tests.peers.scenarios.services import (
    call_bad_args,
    call_missing,
    call_mult,
    call_setbool,
    call_timeout,
    concurrent_calls,
    failing_handler,
    killed_client_service_goes,
    serve_async,
    serve_mult,
    serve_relative_name,
    serve_setbool,
    unadvertise_service,
)
from tests.peers.scenarios.support import (
    ATTEMPT,
    DEADLINE,
)
from tests.peers.scenarios.topics import (
    bad_fields_named,
    bad_type_then_publish,
    big_integers,
    burst_in_order,
    hears_itself,
    non_finite_floats,
    publish_large,
    publish_latched,
    publish_nested,
    publish_ros1_time_keys,
    publish_string,
    relative_names,
    subscribe_best_effort,
    subscribe_large,
    subscribe_latched,
    subscribe_nested,
    subscribe_png,
    subscribe_string,
    subscribe_without_type,
    subscribe_wrong_type,
    subscription_options,
    two_subscriptions,
    unadvertise,
    unsubscribe,
)

__all__ = [
    "ATTEMPT",
    "CBOR_ARRAYS",
    "DEADLINE",
    "FOXGLOVE_PARAMETERS",
    "bad_fields_named",
    "bad_type_then_publish",
    "big_integers",
    "burst_in_order",
    "call_bad_args",
    "call_missing",
    "call_mult",
    "call_setbool",
    "call_timeout",
    "cancel_goal",
    "client_to_client_action",
    "client_to_client_failure",
    "client_to_client_service",
    "client_to_client_topic",
    "concurrent_calls",
    "declare_foxglove_parameters",
    "failing_handler",
    "get_action_servers",
    "get_nodes",
    "get_publishers",
    "get_services",
    "get_time",
    "get_topic_type",
    "get_topics",
    "hears_itself",
    "killed_client_service_goes",
    "latched_to_second_client",
    "message_details",
    "mixed_encodings",
    "non_finite_floats",
    "params",
    "publish_large",
    "publish_latched",
    "publish_nested",
    "publish_ros1_time_keys",
    "publish_string",
    "reconnect_after_bridge_restart",
    "relative_names",
    "send_goal",
    "serve_action",
    "serve_action_canceled",
    "serve_async",
    "serve_mult",
    "serve_relative_name",
    "serve_setbool",
    "service_details",
    "subscribe_best_effort",
    "subscribe_cbor",
    "subscribe_cbor_bytes",
    "subscribe_cbor_raw",
    "subscribe_cbor_typed_array",
    "subscribe_large",
    "subscribe_latched",
    "subscribe_nested",
    "subscribe_png",
    "subscribe_string",
    "subscribe_without_type",
    "subscribe_wrong_type",
    "subscription_options",
    "topics_and_raw_types",
    "two_subscriptions",
    "unadvertise",
    "unadvertise_service",
    "unsubscribe",
]
