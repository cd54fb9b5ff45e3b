"""The wire packet record every judge reads: one packet as a recorder saw it, and its short description.

A close or EOF seen by the recorder is a :class:`WirePacket` with the Chaos opcode CLS / EOF / LOS (its
data: the reason text).  Live probes, replay, ``verify`` and the capture view all make these.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

from manip.codecs.packet import Direction
from manip.spec import SPEC
from manip.spec.constants import ChaosOp

__all__ = ["CLOSE_OPCODES", "Direction", "WirePacket", "describe", "opcode_name", "word"]

CLOSE_OPCODES: Final = frozenset({ChaosOp.CLS, ChaosOp.EOF, ChaosOp.LOS})
"""Pseudo-packets a recorder writes when the connection ends (data: the reason text)."""


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

    @property
    def is_close(self) -> bool:
        return self.opcode in CLOSE_OPCODES

    def to_json(self) -> dict[str, object]:
        return {
            "dir": self.direction,
            "opcode": f"{self.opcode:o}",
            "packet_no": self.packet_no,
            "ack_no": self.ack_no,
            "data": self.data.hex(),
            "time": round(self.time, 6),
            "connection": self.connection,
        }


def word(data: bytes, offset: int = 0) -> int | None:
    """The little-endian word at ``offset``, or None when the data are too short."""
    if len(data) < offset + 2:
        return None
    return int.from_bytes(data[offset : offset + 2], "little")


def describe(packet: WirePacket) -> str:
    """A short human description of a packet: opcode (octal), number and data length.  A request shows
    its Chaos packet number (which its answer must echo), a server packet the request number its first
    data word carries: ``here 0201 (packet number 23, 0 data bytes)``, ``response 0200 (request number
    23, 50 data bytes)``."""
    if packet.is_close:
        reason = packet.data.decode("ascii", "replace")
        close = SPEC.chaos_opcode_name(packet.opcode)
        return f"{close} ({reason})" if reason else close
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
