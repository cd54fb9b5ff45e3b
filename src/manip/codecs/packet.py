"""The Chaos packet as a value: header fields plus data, independent of any link framing.

A packet is eight 16-bit header words followed by ``nbytes`` of data.  How those words become bytes
depends on the link (see :mod:`manip.codecs.framing`); this module knows nothing about bytes on a wire.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

MAX_DATA = 488
"""Largest data field of a Chaos packet, in bytes (clause ``chaos.data.max-488``)."""


@dataclass(frozen=True, slots=True)
class Trailer:
    """The three hardware-trailer words that follow the data on CHUDP, TCP and chaosd links."""

    dest: int
    source: int
    checksum: int


@dataclass(frozen=True, slots=True)
class Packet:
    """One Chaos packet.  ``nbytes`` is always ``len(data)``; ``fc`` is the forwarding count."""

    opcode: int
    dest_host: int = 0
    dest_index: int = 0
    src_host: int = 0
    src_index: int = 0
    packet_no: int = 0
    ack_no: int = 0
    data: bytes = b""
    fc: int = 0
    trailer: Trailer | None = field(default=None, compare=False)

    @property
    def nbytes(self) -> int:
        return len(self.data)

    def with_(self, **changes: object) -> Packet:
        """A copy with some fields changed (``dataclasses.replace`` under a short name)."""
        return replace(self, **changes)  # type: ignore[arg-type]


_new = object.__new__
_slot = Packet.__dict__
_trailer_slot = Trailer.__dict__


def make_packet(
    opcode: int,
    dest_host: int,
    dest_index: int,
    src_host: int,
    src_index: int,
    packet_no: int,
    ack_no: int,
    data: bytes,
    fc: int = 0,
    trailer: Trailer | None = None,
) -> Packet:
    """Build a Packet without the frozen-dataclass ``__init__`` (about twice as fast; for decoders).

    Sets the same slots ``__init__`` would; callers have already validated the values.
    """
    p = _new(Packet)
    _slot["opcode"].__set__(p, opcode)
    _slot["dest_host"].__set__(p, dest_host)
    _slot["dest_index"].__set__(p, dest_index)
    _slot["src_host"].__set__(p, src_host)
    _slot["src_index"].__set__(p, src_index)
    _slot["packet_no"].__set__(p, packet_no)
    _slot["ack_no"].__set__(p, ack_no)
    _slot["data"].__set__(p, data)
    _slot["fc"].__set__(p, fc)
    _slot["trailer"].__set__(p, trailer)
    return p


def make_trailer_value(dest: int, source: int, checksum: int) -> Trailer:
    """Build a Trailer without the frozen-dataclass ``__init__`` (for decoders, like :func:`make_packet`)."""
    t = _new(Trailer)
    _trailer_slot["dest"].__set__(t, dest)
    _trailer_slot["source"].__set__(t, source)
    _trailer_slot["checksum"].__set__(t, checksum)
    return t
