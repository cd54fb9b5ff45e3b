"""Frames laid out with a host's Chaos-level defects (:class:`~manip.ncp.defects.ChaosDefects`).

A link whose defects all keep the rules uses the framing codec's encoders
(:mod:`manip.codecs.framing`); one given a framing defect builds each frame here instead, by the same
steps as the codec (the logical words, the trailer and its checksum, the link's byte order and
delimiter) with the deviation each defect field names.  Only the reference server's fault switches set
such defects, so that the suite can be shown to catch them.
"""

from __future__ import annotations

import struct
from typing import Final

from manip.codecs.chaos import chaos_checksum, header_words
from manip.codecs.framing import CHUDP_HEADER
from manip.codecs.packet import Packet
from manip.ncp.defects import ChaosDefects

__all__ = ["defective_frame"]

_WORD: Final = 0xFFFF


def _data_words(data: bytes, first_low: bool) -> list[int]:
    padded = data + b"\0" if len(data) & 1 else data
    return list(struct.unpack(f"{'<' if first_low else '>'}{len(padded) // 2}H", padded))


def defective_frame(kind: str, p: Packet, hw_dest: int | None, hw_src: int | None, d: ChaosDefects) -> bytes:
    """The frame of ``p`` on a ``kind`` link (``chudp``, ``chaosd``, or the TCP link framing for any
    other: ``tcp`` and ``unix``), laid out with the defects ``d``."""
    header = header_words(p)
    header[0] |= d.header_low_byte & 0xFF
    if d.header_source_first:
        header[2:6] = header[4:6] + header[2:4]
    if len(p.data) & 1 and not d.nbytes_counts_odd_byte:
        header[1] -= 1
    words = header + _data_words(p.data, d.data_first_byte_low)
    dest = p.dest_host if hw_dest is None else hw_dest
    source = p.src_host if hw_src is None else hw_src
    if not d.trailer_source_own:
        source = dest
    checksum = chaos_checksum([*words, dest, source] if d.checksum_covers_trailer else words)
    words += [dest, source, checksum & _WORD]
    msb_first = (
        d.chudp_msb_first if kind == "chudp" else not d.chaosd_little_endian if kind == "chaosd" else True
    )
    body = struct.pack(f"{'>' if msb_first else '<'}{len(words)}H", *words)
    if kind == "chudp":
        if len(p.data) & 1 and not d.chudp_pads_odd_byte:
            pad = 16 + len(p.data) - 1 if msb_first else 16 + len(p.data)  # the zero byte of the last word
            body = body[:pad] + body[pad + 1 :]
        return (CHUDP_HEADER if d.chudp_header else b"") + body
    if kind == "chaosd":
        return bytes((len(body) >> 8, len(body) & 0xFF, 1, 0)) + body
    length = len(body) - (1 if len(p.data) & 1 and not d.tcp_length_counts_pad else 0)
    return length.to_bytes(2, "big") + body
