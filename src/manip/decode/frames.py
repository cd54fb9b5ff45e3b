"""Cut ``manip-decode``'s input into frames, each with its bytes as they were on the wire and where it began.

Stream framings (``tcp``, ``chaosd``) are cut as the blocks arrive, so the first packet is shown before
the rest is read and memory stays bounded by one block and one frame.  ``chudp`` and ``raw`` carry one
packet per input.  A frame that does not decode is reported in place and the stream goes on; a bad
length loses the frame boundaries, which ends the stream (as on a live link).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Final

from manip.codecs.chaos import decode_raw
from manip.codecs.errors import DecodeError
from manip.codecs.framing import (
    ChaosdFrameDecoder,
    StreamDecoder,
    TcpFrameDecoder,
    decode_chudp,
)
from manip.codecs.packet import Packet

SINGLE_LIMIT: Final = 1 << 16
"""The most a one-packet input (``chudp``, ``raw``) may hold; a datagram is at most 514 bytes."""


@dataclass(frozen=True, slots=True)
class Frame:
    """One frame of the input."""

    offset: int
    """Where its first byte is in the input (bytes from the start)."""
    wire: bytes
    """Its bytes as they came."""
    base: int
    """Where the Chaos header starts within ``wire`` (after any framing header)."""
    packet: Packet | None
    error: DecodeError | None
    """Why it does not decode (offsets from the start of the input); for an illegal packet the packet
    is set too."""


@dataclass(frozen=True, slots=True)
class FrameLayout:
    """How a framing lays a packet out: the header before the words, their byte order."""

    prefix: int
    msb_first: bool
    trailer: bool
    note: str


LAYOUTS: Final = {
    "chudp": FrameLayout(
        4, True, True, "CHUDP header 01 01 00 00, then 16-bit words most significant byte first"
    ),
    "tcp": FrameLayout(
        2, True, True, "2-byte big-endian length, then 16-bit words most significant byte first"
    ),
    "chaosd": FrameLayout(
        4, False, True, "4-byte chaosd header, then 16-bit words least significant byte first"
    ),
    "raw": FrameLayout(0, False, False, "PDP-11 memory order: 16-bit words least significant byte first"),
}


class EmptyInputError(DecodeError):
    """The input held no bytes at all."""


def _empty(link: str) -> EmptyInputError:
    return EmptyInputError(f"empty input: no {link} frame to decode", path="input", offset=0)


def _single(blocks: Iterable[bytes], link: str) -> Iterator[Frame]:
    data = b""
    for block in blocks:
        data += block
        if len(data) > SINGLE_LIMIT:
            raise DecodeError(
                f"more than {SINGLE_LIMIT} bytes: a {link} input is one packet "
                "(for a stream of frames use --link tcp or chaosd, for a capture --pcap or --mcap)",
                path="input",
                offset=SINGLE_LIMIT,
            )
    if not data:
        raise _empty(link)
    decode: Callable[[bytes], Packet] = decode_chudp if link == "chudp" else decode_raw
    try:
        yield Frame(0, data, LAYOUTS[link].prefix, decode(data), None)
    except DecodeError as exc:
        packet = getattr(exc, "packet", None)
        yield Frame(0, data, LAYOUTS[link].prefix, packet, exc)


def _stream(blocks: Iterable[bytes], link: str) -> Iterator[Frame]:
    decoder: StreamDecoder = TcpFrameDecoder() if link == "tcp" else ChaosdFrameDecoder()
    prefix = decoder.prefix
    body_length = decoder._body_length  # the framing's own length check (as the capture reader uses)
    buf = bytearray()
    start = 0  # input offset of buf[0]
    seen = False
    for block in blocks:
        seen = seen or bool(block)
        buf += block
        pos = 0
        while len(buf) - pos >= prefix:
            try:
                length = body_length(buf, pos, start + pos)
            except DecodeError as exc:
                raise FramingLostError(exc.message, exc.path, exc.offset, exc.clause) from None
            end = pos + prefix + length
            if len(buf) < end:
                break
            wire = bytes(buf[pos:end])
            yield _one(decoder, wire, start + pos, prefix)
            pos = end
        del buf[:pos]
        start += pos
    if not seen:
        raise _empty(link)
    if buf:
        raise DecodeError(
            f"input ended inside a frame ({len(buf)} bytes of it present)",
            path="frame",
            offset=start,
            clause=decoder.clause,
        )


def _one(decoder: StreamDecoder, wire: bytes, offset: int, prefix: int) -> Frame:
    try:
        packet = decoder._decode(wire, prefix, len(wire), offset + prefix)
    except DecodeError as exc:
        return Frame(offset, wire, prefix, getattr(exc, "packet", None), exc)
    return Frame(offset, wire, prefix, packet, None)


class FramingLostError(DecodeError):
    """A frame length or header is wrong: nothing after it can be found again."""


def frames(blocks: Iterable[bytes], link: str) -> Iterator[Frame]:
    """The frames of ``blocks`` in framing ``link``; EmptyInputError, FramingLostError or a cut-off last frame
    raise :class:`DecodeError` after the frames before them."""
    if link in ("tcp", "chaosd"):
        return _stream(blocks, link)
    return _single(blocks, link)


__all__ = [
    "LAYOUTS",
    "EmptyInputError",
    "Frame",
    "FrameLayout",
    "FramingLostError",
    "frames",
]
