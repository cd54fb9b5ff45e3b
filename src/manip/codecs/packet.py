"""The Chaos packet as a value: header fields plus data, independent of any link framing.

A packet is eight 16-bit header words followed by ``nbytes`` of data.  How those words become bytes
depends on the link (see :mod:`manip.codecs.framing`); this module knows nothing about bytes on a wire.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Literal

Direction = Literal["c2s", "s2c"]
"""Which way a packet travels: client to server, or server to client (the one name for it: captures,
recorders and the conformance checkers all use this one)."""

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


class _PacketBuilder:
    """A plain class with exactly :class:`Packet`'s slots, so an instance can become a Packet.

    Building a frozen dataclass field by field goes through ``object.__setattr__`` (or the slot
    descriptors) once per field, which is most of the cost of a packet on the per-packet path.  This class
    sets the same slots with ordinary attribute stores; :func:`make_packet` then reassigns ``__class__``,
    which Python allows between classes whose instance layouts are identical (same slots, same base).
    The result is an ordinary Packet: same type, fields, equality, hash and immutability.
    """

    __slots__ = Packet.__slots__

    def __init__(
        self,
        opcode: int,
        dest_host: int,
        dest_index: int,
        src_host: int,
        src_index: int,
        packet_no: int,
        ack_no: int,
        data: bytes,
        fc: int,
        trailer: Trailer | None,
    ) -> None:
        self.opcode = opcode
        self.dest_host = dest_host
        self.dest_index = dest_index
        self.src_host = src_host
        self.src_index = src_index
        self.packet_no = packet_no
        self.ack_no = ack_no
        self.data = data
        self.fc = fc
        self.trailer = trailer


class _TrailerBuilder:
    """:class:`_PacketBuilder` for :class:`Trailer`."""

    __slots__ = Trailer.__slots__

    def __init__(self, dest: int, source: int, checksum: int) -> None:
        self.dest = dest
        self.source = source
        self.checksum = checksum


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
    """Build a Packet without the frozen-dataclass ``__init__`` (about three times as fast; for codecs
    and the NCP).  Sets the same slots ``__init__`` would; callers have already validated the values."""
    p = _PacketBuilder(
        opcode, dest_host, dest_index, src_host, src_index, packet_no, ack_no, data, fc, trailer
    )
    p.__class__ = Packet  # type: ignore[assignment]
    return p  # type: ignore[return-value]


def make_trailer_value(dest: int, source: int, checksum: int) -> Trailer:
    """Build a Trailer without the frozen-dataclass ``__init__`` (for decoders, like :func:`make_packet`)."""
    t = _TrailerBuilder(dest, source, checksum)
    t.__class__ = Trailer  # type: ignore[assignment]
    return t  # type: ignore[return-value]
