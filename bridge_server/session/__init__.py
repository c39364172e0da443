"""One client's session: the frame loop and op table (:mod:`.session`), the op
groups (:mod:`.topics`, :mod:`.services`, :mod:`.actions`), the outbox
(:mod:`.outbox`), who serves which name (:mod:`.ownership`), resumable sessions
(:mod:`.resume`) and the ``/rosapi/*`` introspection services (:mod:`.rosapi`).
"""
