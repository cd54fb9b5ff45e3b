"""Link framings: how a Chaos packet (:mod:`manip.codecs.chaos`) becomes bytes on each link manip speaks.

Every link carries the same logical 16-bit words (eight header words, the data as words with the first
byte low, and on most links a three-word hardware trailer); they differ in byte order and in what
delimits a packet.  The trailer is *hardware destination* (next hop; defaults to the packet's destination
host), *hardware source* (our own address; defaults to the packet's source host) and the RFC 1071
checksum over header, padded data, trailer destination and source (:func:`~manip.codecs.chaos.make_trailer`).

``raw``
    The canonical PDP-11 memory order of :mod:`manip.codecs.chaos`: little-endian words, no trailer, one
    packet per buffer.  Used for hex dumps and captures that have already been unwrapped.

``chudp``
    Chaos over UDP as klh10, simh and the global Chaosnet speak it: one packet per datagram, a 4-byte
    header ``01 01 00 00`` (version 1, function 1 = packet, two zero argument bytes), then every word of
    header, padded data and trailer **most significant byte first**, so 8-bit data appear pair-swapped
    (``d1 d0 d3 d2 ...``; an odd last byte goes out as ``00 dN``).  Receivers check the version and
    function bytes only; the argument bytes are ignored.

``tcp``, *manip TCP link framing v1* (our own embedded link)
    A TCP connection carries, in each direction and with no handshake or other bytes, a sequence of
    frames.  A frame is a 2-byte big-endian length ``L`` followed by ``L`` bytes which are exactly a CHUDP
    datagram without its 4-byte header: the eight header words, the data padded to a whole word and the
    trailer, every word most significant byte first, checksum included.  ``L`` must be even and
    ``22 <= L <= 510`` (16 + 488 + 6); any other ``L`` is a framing error (clause ``link.tcp.framing``)
    after which the receiver cannot find the next frame and must drop the connection.  Within a
    well-formed ``L`` the packet must fill the frame exactly (``L == 16 + padded nbytes + 6``, clause
    ``chaos.header.nbytes``) and its checksum must verify (``chudp.checksum``); a frame that fails is
    skipped (``L`` says where the next one starts) and reported, and the stream goes on.  Reusing the
    CHUDP body means one decoder, a checksum that catches corruption above TCP's, and a bridge between the
    two links that only adds or strips four bytes.

``chaosd``
    usim's unix-socket link to a chaosd daemon: a 4-byte header ``len >> 8, len & 0xFF, 1, 0`` where
    ``len`` counts the bytes that follow (header, padded data and trailer, always even), then those words
    **little-endian**, as the emulated CADR holds them in memory.  Clause ``link.chaosd.framing``.  The
    checksum is written over the logical words like CHUDP's, but not verified by default: usim ignores it
    on receipt and computes it over byte-swapped words on transmit, so a strict check would refuse real
    usim traffic.

Stream links (``tcp``, ``chaosd``) have a decoder class: feed it bytes in any chunks and it returns what
the bytes completed, as a list of :class:`~manip.codecs.packet.Packet` or
:class:`~manip.codecs.errors.DecodeError` items in stream order (a malformed frame is consumed and
reported in place, so the caller sees it and carries on).  A bad length or header means the frame
boundaries are lost: ``feed`` then raises :class:`FrameSyncError`, which carries the items decoded before
it, and every later ``feed`` raises it again.  All error offsets count from the start of the stream.

:data:`FRAMINGS` maps each name to a :class:`Framing`, for command-line tools that pick a link by name.
"""

from __future__ import annotations

import struct
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import ClassVar, Final, Literal

from manip.codecs.chaos import (
    HEADER_SIZE,
    TRAILER_SIZE,
    WordLocator,
    chaos_checksum,
    check_data_length,
    check_encodable,
    check_header,
    checksum_ok,
    decode_raw,
    encode_raw,
    make_trailer,
    packet_from_words,
    packet_words,
    padded_size,
)
from manip.codecs.errors import DecodeError
from manip.codecs.packet import MAX_DATA, Packet, Trailer

CHUDP_HEADER: Final = b"\x01\x01\x00\x00"
"""Version 1, function 1 (a Chaos packet), two zero argument bytes."""
CHUDP_VERSION: Final = 1
CHUDP_PKT: Final = 1
MIN_BODY: Final = HEADER_SIZE + TRAILER_SIZE
"""Smallest packet-plus-trailer: no data (22 bytes)."""
MAX_BODY: Final = HEADER_SIZE + MAX_DATA + TRAILER_SIZE
"""Largest packet-plus-trailer: 488 data bytes (510 bytes)."""

WordOrder = Literal["<", ">"]
StreamItem = Packet | DecodeError
"""What a stream decoder returns for each frame: the packet, or why that frame was refused."""


# ------------------------------------------------------------------------------------ shared body


def _body(p: Packet, order: WordOrder, hw_dest: int | None, hw_src: int | None) -> bytes:
    """Header, padded data and trailer as words in ``order``: the part every trailer-carrying link shares."""
    check_encodable(p)
    trailer = make_trailer(p, hw_dest, hw_src)
    words = packet_words(p)
    return struct.pack(f"{order}{len(words) + 3}H", *words, trailer.dest, trailer.source, trailer.checksum)


def _decode_body(body: bytes, base: int, order: WordOrder, *, verify: bool) -> Packet:
    """Decode header, padded data and trailer that a framing has delimited; ``base`` is its input offset.

    The checksum is tested first: when it fails, nothing else in the frame can be trusted, and a corrupt
    count or opcode would otherwise be reported as if the sender had meant it.  The caller guarantees an
    even length of at least :data:`MIN_BODY`.
    """
    n = len(body) // 2
    words = struct.unpack(f"{order}{n}H", body)
    if verify and not checksum_ok(words):
        expected = chaos_checksum(words[:-1])
        raise DecodeError(
            f"checksum is {words[-1]:#06x}, expected {expected:#06x}",
            path="trailer.checksum",
            offset=base + len(body) - 2,
            clause="chudp.checksum",
        )
    at = WordLocator(base, msb_first=order == ">")
    nbytes = check_header(words[0], words[1], at)
    check_data_length(nbytes, len(body) - MIN_BODY, at, exact=True)
    if order == "<":
        data = bytes(body[HEADER_SIZE : HEADER_SIZE + nbytes])
    else:
        count = padded_size(nbytes) // 2
        data = struct.pack(f"<{count}H", *words[8 : 8 + count])[:nbytes]
    return packet_from_words(words[:8], data, Trailer(*words[-3:]))


def _check_body_length(length: int, offset: int, clause: str, what: str) -> None:
    if length & 1 or not MIN_BODY <= length <= MAX_BODY:
        raise DecodeError(
            f"{what} {length} is not an even number from {MIN_BODY} to {MAX_BODY}",
            path="length",
            offset=offset,
            clause=clause,
        )


# ------------------------------------------------------------------------------------ CHUDP


def encode_chudp(p: Packet, *, hw_dest: int | None = None, hw_src: int | None = None) -> bytes:
    """One CHUDP datagram (UDP payload) carrying ``p``; see the module docstring for the layout."""
    return CHUDP_HEADER + _body(p, ">", hw_dest, hw_src)


def decode_chudp(datagram: bytes, *, verify: bool = True) -> Packet:
    """Decode one CHUDP datagram; the packet's ``trailer`` is filled in.

    ``verify=False`` skips the checksum test, to look at a corrupt datagram instead of refusing it.
    """
    size = len(datagram)
    if size < len(CHUDP_HEADER):
        raise DecodeError(
            f"{size} bytes is shorter than the 4-byte CHUDP header",
            path="chudp",
            offset=size,
            clause="chudp.length",
        )
    for index, name, want in ((0, "version", CHUDP_VERSION), (1, "function", CHUDP_PKT)):
        if datagram[index] != want:
            raise DecodeError(
                f"CHUDP {name} is {datagram[index]}, expected {want}",
                path=f"chudp.{name}",
                offset=index,
                clause="chudp.header",
            )
    body = size - len(CHUDP_HEADER)
    if body < MIN_BODY or body & 1:
        raise DecodeError(
            f"{size}-byte datagram: after the 4-byte header a CHUDP datagram holds an even number "
            f"of at least {MIN_BODY} bytes (header words and trailer)",
            path="chudp",
            offset=size,
            clause="chudp.length",
        )
    return _decode_body(bytes(datagram[4:]), 4, ">", verify=verify)


# ------------------------------------------------------------------------------------ stream links


@dataclass(eq=False)
class FrameSyncError(DecodeError):
    """A stream's frame boundaries are lost (bad length or header); the connection must be dropped.

    ``items`` holds what the same :meth:`StreamDecoder.feed` call decoded before the bad frame, so a
    caller that catches this loses nothing.
    """

    items: tuple[StreamItem, ...] = field(default=())


class StreamDecoder(ABC):
    """Reassembles length-prefixed frames from a byte stream fed in arbitrary chunks (sans I/O)."""

    prefix: ClassVar[int]
    """Bytes of frame header before the body."""
    clause: ClassVar[str]
    """The clause a framing error of this link breaks."""

    def __init__(self, *, verify: bool = True) -> None:
        self.verify = verify
        self._buf = bytearray()
        self._start = 0  # stream offset of self._buf[0]
        self._failed: FrameSyncError | None = None

    @property
    def offset(self) -> int:
        """Stream bytes fed so far."""
        return self._start + len(self._buf)

    @property
    def pending(self) -> int:
        """Bytes held back because their frame is not complete yet."""
        return len(self._buf)

    @property
    def failed(self) -> FrameSyncError | None:
        """The framing error that stopped this decoder, if any."""
        return self._failed

    @abstractmethod
    def _body_length(self, header: bytes, offset: int) -> int:
        """Validate a frame header found at stream ``offset``; return the body length."""

    @abstractmethod
    def _decode(self, body: bytes, offset: int) -> Packet:
        """Decode one frame body found at stream ``offset``."""

    def feed(self, data: bytes) -> list[StreamItem]:
        """Add ``data``; return the packets (or per-frame errors) of every frame now complete, in order."""
        if self._failed is not None:
            raise self._failed
        buf = self._buf
        buf += data
        items: list[StreamItem] = []
        pos = 0
        while len(buf) - pos >= self.prefix:
            here = self._start + pos
            try:
                length = self._body_length(bytes(buf[pos : pos + self.prefix]), here)
            except DecodeError as exc:
                del buf[:pos]
                self._start += pos
                self._failed = FrameSyncError(exc.message, exc.path, exc.offset, exc.clause, tuple(items))
                raise self._failed from None
            end = pos + self.prefix + length
            if len(buf) < end:
                break
            try:
                items.append(self._decode(bytes(buf[pos + self.prefix : end]), here + self.prefix))
            except DecodeError as exc:
                items.append(exc)
            pos = end
        del buf[:pos]
        self._start += pos
        return items

    def finish(self) -> None:
        """Declare the end of the stream; raise :class:`DecodeError` if it stopped inside a frame."""
        if self._failed is not None:
            raise self._failed
        if self._buf:
            raise DecodeError(
                f"stream ended inside a frame ({len(self._buf)} bytes of it received)",
                path="frame",
                offset=self._start,
                clause=self.clause,
            )


class TcpFrameDecoder(StreamDecoder):
    """Decoder for manip TCP link framing v1 (see the module docstring)."""

    prefix = 2
    clause = "link.tcp.framing"

    def _body_length(self, header: bytes, offset: int) -> int:
        length = int.from_bytes(header, "big")
        _check_body_length(length, offset, self.clause, "frame length")
        return length

    def _decode(self, body: bytes, offset: int) -> Packet:
        return _decode_body(body, offset, ">", verify=self.verify)


class ChaosdFrameDecoder(StreamDecoder):
    """Decoder for usim's chaosd socket stream; checksums are not verified unless asked (module docstring)."""

    prefix = 4
    clause = "link.chaosd.framing"

    def __init__(self, *, verify: bool = False) -> None:
        super().__init__(verify=verify)

    def _body_length(self, header: bytes, offset: int) -> int:
        if header[2:4] != b"\x01\x00":
            raise DecodeError(
                f"chaosd frame header bytes 2-3 are {header[2:4].hex(' ')}, expected 01 00",
                path="frame.header",
                offset=offset + 2,
                clause=self.clause,
            )
        length = header[0] << 8 | header[1]
        _check_body_length(length, offset, self.clause, "chaosd length")
        return length

    def _decode(self, body: bytes, offset: int) -> Packet:
        return _decode_body(body, offset, "<", verify=self.verify)


def _one_frame(decoder: StreamDecoder, frame: bytes) -> Packet:
    """Decode a buffer that must hold exactly one frame."""
    items = decoder.feed(frame)
    decoder.finish()
    if len(items) != 1:
        raise DecodeError(
            f"expected one frame, found {len(items)}",
            path="frame",
            offset=0,
            clause=decoder.clause,
        )
    (item,) = items
    if isinstance(item, DecodeError):
        raise item
    return item


def decode_stream(decoder: StreamDecoder, data: bytes) -> list[Packet]:
    """All packets of a complete stream capture; the first bad frame (or a cut-off last one) raises."""
    items = decoder.feed(data)
    decoder.finish()
    packets: list[Packet] = []
    for item in items:
        if isinstance(item, DecodeError):
            raise item
        packets.append(item)
    return packets


def encode_tcp(p: Packet, *, hw_dest: int | None = None, hw_src: int | None = None) -> bytes:
    """One frame of manip TCP link framing v1 carrying ``p``."""
    body = _body(p, ">", hw_dest, hw_src)
    return len(body).to_bytes(2, "big") + body


def decode_tcp(frame: bytes, *, verify: bool = True) -> Packet:
    """Decode a buffer holding exactly one TCP-link frame."""
    return _one_frame(TcpFrameDecoder(verify=verify), frame)


def encode_chaosd(p: Packet, *, hw_dest: int | None = None, hw_src: int | None = None) -> bytes:
    """One chaosd socket frame carrying ``p`` (trailer words little-endian like the rest)."""
    body = _body(p, "<", hw_dest, hw_src)
    return bytes((len(body) >> 8, len(body) & 0xFF, 1, 0)) + body


def decode_chaosd(frame: bytes, *, verify: bool = False) -> Packet:
    """Decode a buffer holding exactly one chaosd frame (checksum checked only with ``verify=True``)."""
    return _one_frame(ChaosdFrameDecoder(verify=verify), frame)


# ------------------------------------------------------------------------------------ registry


@dataclass(frozen=True)
class Framing:
    """A link framing by name: ``decode`` returns every packet in the buffer and raises on the first error."""

    name: str
    description: str
    stream: bool
    encode: Callable[[Packet], bytes]
    decode: Callable[[bytes], list[Packet]]


def _decode_chudp_list(data: bytes) -> list[Packet]:
    return [decode_chudp(data)]


def _decode_raw_list(data: bytes) -> list[Packet]:
    return [decode_raw(data)]


def _decode_tcp_stream(data: bytes) -> list[Packet]:
    return decode_stream(TcpFrameDecoder(), data)


def _decode_chaosd_stream(data: bytes) -> list[Packet]:
    return decode_stream(ChaosdFrameDecoder(), data)


def _encode_chudp(p: Packet) -> bytes:
    return encode_chudp(p)


def _encode_tcp(p: Packet) -> bytes:
    return encode_tcp(p)


def _encode_chaosd(p: Packet) -> bytes:
    return encode_chaosd(p)


FRAMINGS: Final[Mapping[str, Framing]] = MappingProxyType(
    {
        f.name: f
        for f in (
            Framing(
                "chudp",
                "Chaos over UDP (klh10, simh): 01 01 00 00, then MSB-first words with trailer",
                False,
                _encode_chudp,
                _decode_chudp_list,
            ),
            Framing(
                "tcp",
                "manip TCP link v1: 2-byte big-endian length, then a CHUDP datagram minus its header",
                True,
                _encode_tcp,
                _decode_tcp_stream,
            ),
            Framing(
                "chaosd",
                "usim chaosd socket: len>>8, len&0xFF, 1, 0, then little-endian words with trailer",
                True,
                _encode_chaosd,
                _decode_chaosd_stream,
            ),
            Framing(
                "raw",
                "canonical PDP-11 memory order: little-endian words, no trailer, one packet",
                False,
                encode_raw,
                _decode_raw_list,
            ),
        )
    }
)
"""Every framing by name: ``chudp``, ``tcp``, ``chaosd``, ``raw``."""
