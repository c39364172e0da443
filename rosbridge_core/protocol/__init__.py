"""The rosbridge v2 protocol core, shared by the client and the bridge.

Sans-I/O and standard library only (``cbor2`` once a binary frame arrives): it imports no
other module of the client, so the bridge (``bridge_server``) and the relay use it without
loading the client. A test keeps it so (``tests/core/test_protocol_core.py``).

- :mod:`~rosbridge_core.protocol.ops`: every op as a frozen dataclass, parsed and serialized
  in one place (the kinds its fields may hold: :mod:`~rosbridge_core.protocol.kinds`), and
  the handshake headers (:mod:`~rosbridge_core.protocol.headers`, re-exported by ``ops``);
- :mod:`~rosbridge_core.protocol.frames`: websocket frames in (JSON text, CBOR binary with
  RFC 8746 typed arrays), ``fragment`` ops reassembled and made (:class:`Conversation`);
- :mod:`~rosbridge_core.protocol.keepalive`: how a link notices its peer went silent;
- :mod:`~rosbridge_core.protocol.errors`: the root of every roslibpy_lite error and the
  protocol errors (the client's other errors grow from it in :mod:`roslibpy_lite.exceptions`);
- :mod:`~rosbridge_core.protocol.goal_status`: :class:`GoalStatus`, a goal's status numbers.

The frame API is re-exported here, where it has always been found
(``rosbridge_core.protocol.Conversation``, ``rosbridge_core.protocol.decode_frame``).
"""

from __future__ import annotations

from .frames import *  # noqa: F403  (the frame API, as frames.__all__ lists it)
from .frames import __all__ as __all__
