"""The wire packet record every judge reads: one packet as a recorder saw it, and its short description.

A close or EOF seen by the recorder is a :class:`WirePacket` with the Chaos opcode CLS / EOF / LOS (its
data: the reason text).  Live probes, replay, ``verify`` and the capture view all make these.

A Cougar probe records its DRV-11J link the same way (``link`` :data:`DRV11J`): the words of each
command frame it sent (``c2s``, Puma to Cougar) and of each response Cougar sent (``s2c``), the data the
words little-endian as they travel, the opcode the first (code) word, the packet number the tick.  A
case that plays the link by hand records its frames whole (:data:`DRV11J_FRAME`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

from manip.codecs.cougar import CougarDirection, lookup
from manip.codecs.packet import Direction
from manip.cougar.link import FrameType
from manip.spec import SPEC
from manip.spec.constants import ChaosOp

__all__ = [
    "CLOSE_OPCODES",
    "DRV11J",
    "DRV11J_FRAME",
    "Direction",
    "WirePacket",
    "carries_data",
    "describe",
    "link_words",
    "opcode_name",
    "word",
]

CLOSE_OPCODES: Final = frozenset({ChaosOp.CLS, ChaosOp.EOF, ChaosOp.LOS})
"""Pseudo-packets a recorder writes when the connection ends (data: the reason text)."""
DRV11J: Final = "drv11j"
"""The ``link`` of a Cougar probe's records: Table 1 words on the DRV-11J link, not a Chaos packet."""
DRV11J_FRAME: Final = "drv11j-frame"
"""The ``link`` of a raw DRV-11J link's records (the link's error cases): the bytes of whole frames,
the opcode the first frame's type word."""


@dataclass(frozen=True, slots=True)
class WirePacket:
    """One packet as a recorder saw it.  ``time``: seconds from the start of the recording."""

    direction: Direction
    opcode: int
    packet_no: int
    ack_no: int
    data: bytes
    time: float = 0.0
    connection: int = 0
    """Which connection of a case (0, 1, ...) the packet belongs to."""
    link: str = ""
    """Empty for a Chaos packet; :data:`DRV11J` for the words of a Cougar command or response."""

    @property
    def is_close(self) -> bool:
        return not self.link and self.opcode in CLOSE_OPCODES

    def to_json(self) -> dict[str, object]:
        return {
            "dir": self.direction,
            "opcode": f"{self.opcode:o}",
            "packet_no": self.packet_no,
            "ack_no": self.ack_no,
            "data": self.data.hex(),
            "time": round(self.time, 6),
            "connection": self.connection,
        } | ({"link": self.link} if self.link else {})


def carries_data(packet: WirePacket) -> bool:
    """A data packet of a manip session or a DRV-11J record: neither a Chaos control packet (RFC, OPN,
    STS...) nor a close."""
    return bool(packet.link) or packet.opcode >= ChaosOp.DAT


def word(data: bytes, offset: int = 0) -> int | None:
    """The little-endian word at ``offset``, or None when the data are too short."""
    if len(data) < offset + 2:
        return None
    return int.from_bytes(data[offset : offset + 2], "little")


def describe(packet: WirePacket) -> str:
    """A short human description of a packet: opcode (octal), number and data length.  A request shows
    its Chaos packet number (which its answer must echo), a server packet the request number its first
    data word carries: ``here 0201 (packet number 23, 0 data bytes)``, ``response 0200 (request number
    23, 50 data bytes)``.  A Chaos control packet (a client's recording has them) shows its Chaos name, its
    number and its ack: ``OPN 02 (packet number 1, ack 5)``."""
    if packet.link == DRV11J:
        return _describe_words(packet)
    if packet.link == DRV11J_FRAME:
        return _describe_frames(packet)
    if packet.is_close:
        reason = packet.data.decode("ascii", "replace")
        close = SPEC.chaos_opcode_name(packet.opcode)
        return f"{close} ({reason})" if reason else close
    if packet.opcode < ChaosOp.DAT:
        control = SPEC.chaos_opcode_name(packet.opcode)
        return f"{control} 0{packet.opcode:o} (packet number {packet.packet_no}, ack {packet.ack_no})"
    name = opcode_name(packet)
    if packet.direction == "c2s":
        shown = f"packet number {packet.packet_no}"
    else:
        number = word(packet.data)
        shown = "no request number" if number is None else f"request number {number}"
    return f"{name} 0{packet.opcode:o} ({shown}, {len(packet.data)} data bytes)"


def opcode_name(packet: WirePacket) -> str:
    if packet.direction == "c2s":
        op = SPEC.requests.get(packet.opcode)
        return op.name if op else "unknown-request"
    server = SPEC.server_opcodes.get(packet.opcode)
    return server.name if server else "unknown-server-opcode"


def link_words(packet: WirePacket) -> tuple[int, ...]:
    """The 16-bit words a DRV-11J record carries (its data little-endian)."""
    data = packet.data
    return tuple(int.from_bytes(data[i : i + 2], "little") for i in range(0, len(data) - 1, 2))


def _describe_words(packet: WirePacket) -> str:
    """A DRV-11J record: ``RFRC 9 to Cougar (1 word, tick 3)``, ``FORCES 7 from Cougar (13 words,
    tick 3)``."""
    direction: CougarDirection = "command" if packet.direction == "c2s" else "response"
    words = link_words(packet)
    try:
        name = lookup(direction, packet.opcode).name if words else "nothing"
    except KeyError:
        name = f"unknown {direction}"
    way = "to Cougar" if packet.direction == "c2s" else "from Cougar"
    count = f"{len(words)} word{'s' if len(words) != 1 else ''}"
    return f"{name} {packet.opcode} {way} ({count}, tick {packet.packet_no})"


def _describe_frames(packet: WirePacket) -> str:
    """A raw DRV-11J record: ``TICKED frame from Cougar (10 bytes)``."""
    try:
        kind = f"{FrameType(packet.opcode).name} frame"
    except ValueError:
        kind = f"frame of type {packet.opcode}"
    way = "to Cougar" if packet.direction == "c2s" else "from Cougar"
    return f"{kind} {way} ({len(packet.data)} bytes)"
