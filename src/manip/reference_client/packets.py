"""Packets from the server as the client sees them, and where their request number is.

A transport hands the background process :class:`ServerPacket` objects and says, through
``get_response_info``, what the matching core needs of each: the response code, the request number,
and where the response data start (:class:`ResponseInfo`; the 1985 guide's four values of
``:get-response-info``, with a byte offset in place of an ART-16B index).

For the Chaos manipulator protocol :func:`chaos_response_info` is that function: the response code is
the Chaos opcode minus 0200 (so 0200 RESPONSE is the Manip normal-response code 0, 0201 fatal error is
1, ...), and the request number is the first data word, low byte first.  The Chaos ack field is the
NCP's business and is never used for matching (erratum ``echo-vs-ack``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

from manip.codecs.errors import DecodeError

RESPONSE_OPCODE_BASE: Final = 0o200
"""Chaos opcode of response code 0; response code n travels as opcode 0200 + n."""
REQUEST_NUMBER_BYTES: Final = 2


@dataclass(frozen=True, slots=True)
class ServerPacket:
    """One packet from the server: its Chaos opcode and data (and, for logs, its Chaos numbers)."""

    opcode: int
    data: bytes
    packet_number: int | None = None
    ack_number: int | None = None


@dataclass(frozen=True, slots=True)
class ResponseInfo:
    """What ``get_response_info`` says about a packet."""

    code: int
    """The Manip response code (0 normal response, 1 fatal, 2 non-fatal, 3 asynchronous response,
    4 asynchronous error, 5 asynchronous warning, others per protocol)."""
    request_number: int
    data_offset: int
    """Byte offset in ``packet.data`` where the response data start."""
    data_bytes: int
    """Number of response data bytes (may be zero)."""

    def payload(self, packet: ServerPacket) -> bytes:
        return packet.data[self.data_offset : self.data_offset + self.data_bytes]


def chaos_response_info(packet: ServerPacket) -> ResponseInfo:
    """The response info of a Chaos manipulator protocol packet (request number in data word 0)."""
    if packet.opcode < RESPONSE_OPCODE_BASE:
        raise DecodeError(
            f"opcode 0{packet.opcode:o} is not a data opcode",
            path="opcode",
            offset=0,
            clause="response.server-opcodes",
        )
    if len(packet.data) < REQUEST_NUMBER_BYTES:
        raise DecodeError(
            f"{len(packet.data)} data bytes; the request number needs 2",
            path="request_number",
            offset=len(packet.data),
            clause="response.echoes-request-number",
        )
    number = int.from_bytes(packet.data[:REQUEST_NUMBER_BYTES], "little")
    return ResponseInfo(
        code=packet.opcode - RESPONSE_OPCODE_BASE,
        request_number=number,
        data_offset=REQUEST_NUMBER_BYTES,
        data_bytes=len(packet.data) - REQUEST_NUMBER_BYTES,
    )
