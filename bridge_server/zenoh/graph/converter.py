"""The relay's :class:`~rosbridge_core.graph.Converter`: a ``msgs`` message class's
(:class:`~rosbridge_core.codec.msgs_types.MsgsConverter`) that also reads the CDR bytes a
robot put, as JSON text straight from them and as CBOR."""

from __future__ import annotations

from typing import Any

import cbor2

from msgs import cdr
from msgs.runtime import Message as WireMessage
from rosbridge_core.codec.cdr_json import JsonFromCdr, msgs_encoder
from rosbridge_core.codec.msgs_types import MsgsConverter

__all__ = ["RelayConverter"]


class RelayConverter(MsgsConverter):
    """:class:`~rosbridge_core.graph.Converter` of one ``msgs`` message class (the relay's
    messages are ``msgs`` instances, as the in-memory graph's), reading CDR too."""

    def __init__(self, cls: type[WireMessage]) -> None:
        super().__init__(cls)
        self.decode = cdr.decoder_for(cls)
        self.decode_cbor = cdr.decoder_for(cls, typed=cbor2.CBORTag)  # typed arrays, as the
        # bridge's CBOR sends them (RFC 8746)
        self.json_from_cdr: JsonFromCdr = msgs_encoder(cls)

    def to_cbor_obj(self, msg: Any) -> Any:
        """The message as a CBOR-ready dict (byte strings, numeric arrays typed)."""
        return self.decode_cbor(cdr.encode(msg))

    def text_of(self, data: bytes) -> str:
        """The message's JSON text from its CDR bytes."""
        text = self.json_from_cdr(data)
        if text is None:  # a NaN or infinity: null, as rosbridge sends them
            text = self.to_json(self.cls.from_json(self.decode(data)))
        return text

