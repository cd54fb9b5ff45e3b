"""Small helpers about Chaos packets as the NCP sees them: opcode classes, the 16-bit items of OPN and
STS, and building a LOS by reflecting the packet it complains about."""

from __future__ import annotations

import struct
from typing import Final

from manip.codecs.chaos import is_legal_opcode  # the codec's test: one definition of legality
from manip.codecs.packet import MAX_DATA, Packet
from manip.spec.constants import ChaosOp

__all__ = [
    "MAX_DATA",
    "is_data",
    "is_legal_opcode",
    "make_los",
    "pack_status",
    "text",
    "unpack_status",
]

_STATUS: Final = struct.Struct("<HH")
# A plain int: reading an attribute of the ChaosOp enum class costs more than the comparison itself.
_DAT: Final = int(ChaosOp.DAT)


def is_data(opcode: int) -> bool:
    """Data opcodes: 0200-0277 (8-bit) and 0300-0377 (16-bit)."""
    return _DAT <= opcode <= 0o377


def pack_status(receipt: int, window: int) -> bytes:
    """The data of an OPN or STS: receipt and window as 16-bit items, low byte first."""
    return _STATUS.pack(receipt & 0xFFFF, window & 0xFFFF)


def unpack_status(data: bytes) -> tuple[int, int] | None:
    """(receipt, window) from an OPN's or STS's data, or None when there are fewer than four bytes."""
    if len(data) < _STATUS.size:
        return None
    receipt, window = _STATUS.unpack_from(data)
    return receipt, window


def text(data: bytes) -> str:
    """Reason and contact texts: bytes to str one for one (Latin-1), so nothing is ever rejected."""
    return data.decode("latin-1")


def make_los(offending: Packet, address: int, reason: str) -> Packet:
    """The LOS answering ``offending``: addresses and indices swapped, packet and ack numbers kept."""
    return Packet(
        opcode=ChaosOp.LOS,
        dest_host=offending.src_host,
        dest_index=offending.src_index,
        src_host=address,
        src_index=offending.dest_index,
        packet_no=offending.packet_no,
        ack_no=offending.ack_no,
        data=reason.encode("latin-1"),
    )
