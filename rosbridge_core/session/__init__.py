"""One client's session: the frame loop and op table (:mod:`.session`), the op
groups (:mod:`.topics`, :mod:`.services`, :mod:`.actions`) with the handle they get
(:mod:`.host`), the limits they keep (:mod:`.limits`) and the tasks their requests run in
(:mod:`.calls`), the outbox (:mod:`.outbox`),
who serves which name (:mod:`.ownership`), resumable sessions (:mod:`.resume`) and the
``/rosapi/*`` introspection services (:mod:`.rosapi`). ROS is reached only through the
:class:`~rosbridge_core.graph.Graph`, the client only through its link
(:class:`~.link.ClientLink`, framed as in :mod:`.frames`), the rest of the server only
through what the sessions share (:class:`~.host.Shared`); the settings are :mod:`.config`.
"""
