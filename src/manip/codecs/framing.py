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
reported in place, so the caller sees it and carries on; a sound frame holding an illegal packet is
reported as an :class:`~manip.codecs.chaos.IllegalPacketError`, which carries the packet).  A bad length
or header means the frame boundaries are lost: ``feed`` then raises :class:`FrameSyncError`, which
carries the items decoded before it, and every later ``feed`` raises it again.  All error offsets count
from the start of the stream.

:data:`FRAMINGS` maps each name to a :class:`Framing`, for command-line tools that pick a link by name.
"""

from __future__ import annotations

import struct
from abc import ABC, abstractmethod
from array import array
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import ClassVar, Final, Literal

from manip.codecs.chaos import (
    HEADER_SIZE,
    LEGAL_OPCODES,
    TRAILER_SIZE,
    IllegalPacketError,
    WordLocator,
    chaos_checksum,
    check_encodable,
    checked_packet,
    checksum_ok,
    decode_raw,
    encode_raw,
    make_trailer,
    packet_words,
    padded_size,
)
from manip.codecs.errors import DecodeError
from manip.codecs.packet import MAX_DATA, Packet, Trailer, make_packet, make_trailer_value

CHUDP_HEADER: Final = b"\x01\x01\x00\x00"
"""Version 1, function 1 (a Chaos packet), two zero argument bytes."""
CHUDP_VERSION: Final = 1
CHUDP_PKT: Final = 1
MIN_BODY: Final = HEADER_SIZE + TRAILER_SIZE
"""Smallest packet-plus-trailer: no data (22 bytes)."""
MAX_BODY: Final = HEADER_SIZE + MAX_DATA + TRAILER_SIZE
"""Largest packet-plus-trailer: 488 data bytes (510 bytes)."""

WordOrder = Literal["<", ">"]
Buffer = bytes | bytearray | memoryview
StreamItem = Packet | DecodeError
"""What a stream decoder returns for each frame: the packet, or why that frame was refused (for an
illegal but sound packet an :class:`IllegalPacketError`, which holds the packet)."""


# ------------------------------------------------------------------------------------ shared body
#
# Every packet a link moves goes through :func:`_body` and :func:`_decode_body`, so both have a fast
# path for the well-formed case (checks inline, the data handled as one block, not word by word).
# Anything the fast path is not sure of goes to the checked versions (``_body_checked``,
# ``_decode_body_checked``), which are the reference: they raise the precise errors, and tests check
# the two paths give identical results on random packets and frames.


_HEAD: Final = {">": struct.Struct(">8H"), "<": struct.Struct("<8H")}
_TRAILER: Final = {">": struct.Struct(">3H"), "<": struct.Struct("<3H")}
_TCP_HEAD: Final = struct.Struct(">H8H")  # the frame length, then the header words


def _ones_sum(total: int) -> int:
    """The RFC 1071 (end-around carry) sum of 16-bit words whose plain sum is ``total``, or whose bytes
    read as one integer (in either byte order) are ``total``: both are congruent to it modulo 0xFFFF."""
    return (total - 1) % 0xFFFF + 1 if total else 0


def _fast_body(
    p: Packet, order: WordOrder, hw_dest: int | None, hw_src: int | None, tcp: bool
) -> bytes | None:
    """:func:`_body` for a packet whose fields all fit (None otherwise), with the TCP length if ``tcp``.

    The data are never split into words: the checksum takes them as one integer (2^16 is 1 modulo
    0xFFFF, so that integer is congruent to the sum of its words), and the big-endian links swap each
    byte pair with ``array.byteswap``.
    """
    data = p.data
    n = len(data)
    opcode = p.opcode
    fc = p.fc
    dh = p.dest_host
    di = p.dest_index
    sh = p.src_host
    si = p.src_index
    pn = p.packet_no
    an = p.ack_no
    dest = dh if hw_dest is None else hw_dest
    source = sh if hw_src is None else hw_src
    if not (
        isinstance(opcode, int)
        and isinstance(fc, int)
        and isinstance(dh, int)
        and isinstance(di, int)
        and isinstance(sh, int)
        and isinstance(si, int)
        and isinstance(pn, int)
        and isinstance(an, int)
        and isinstance(dest, int)
        and isinstance(source, int)
        and isinstance(data, bytes)
        and n <= MAX_DATA
        and 0 <= opcode <= 0xFF
        and 0 <= fc <= 0xF
        and 0 <= dh <= 0xFFFF
        and 0 <= di <= 0xFFFF
        and 0 <= sh <= 0xFFFF
        and 0 <= si <= 0xFFFF
        and 0 <= pn <= 0xFFFF
        and 0 <= an <= 0xFFFF
        and 0 <= dest <= 0xFFFF
        and 0 <= source <= 0xFFFF
    ):
        return None
    if n & 1:
        data += b"\0"
    w0 = opcode << 8
    w1 = fc << 12 | n
    total = w0 + w1 + dh + di + sh + si + pn + an + dest + source + int.from_bytes(data, "little")
    checksum = ~_ones_sum(total) & 0xFFFF
    if order == ">":
        swapped = array("H", data)
        swapped.byteswap()
        data = swapped.tobytes()
    trailer = _TRAILER[order].pack(dest, source, checksum)
    if tcp:
        return _TCP_HEAD.pack(MIN_BODY + len(data), w0, w1, dh, di, sh, si, pn, an) + data + trailer
    return _HEAD[order].pack(w0, w1, dh, di, sh, si, pn, an) + data + trailer


def _body(p: Packet, order: WordOrder, hw_dest: int | None, hw_src: int | None) -> bytes:
    """Header, padded data and trailer as words in ``order``: the part every trailer-carrying link shares."""
    body = _fast_body(p, order, hw_dest, hw_src, False)
    return _body_checked(p, order, hw_dest, hw_src) if body is None else body


def _body_checked(p: Packet, order: WordOrder, hw_dest: int | None, hw_src: int | None) -> bytes:
    """:func:`_body` by the book: every field checked (the precise :class:`EncodeError`), then packed."""
    check_encodable(p)
    trailer = make_trailer(p, hw_dest, hw_src)
    words = packet_words(p)
    return struct.pack(f"{order}{len(words) + 3}H", *words, trailer.dest, trailer.source, trailer.checksum)


def _decode_body(buf: Buffer, start: int, end: int, base: int, order: WordOrder, *, verify: bool) -> Packet:
    """Decode the header, padded data and trailer in ``buf[start:end]``; ``base`` is its input offset.

    The caller guarantees an even length of at least :data:`MIN_BODY`.  This is the fast path (the
    checksum is taken over the body read as one integer, as in :func:`_fast_body`); a frame it has any
    doubt about is decoded again by :func:`_decode_body_checked`, which says what is wrong.
    """
    big = order == ">"
    if verify:
        total = int.from_bytes(memoryview(buf)[start:end], "big" if big else "little")
        if total % 0xFFFF or not total:  # the words do not sum to 0xFFFF (ones' complement)
            return _decode_body_checked(bytes(buf[start:end]), base, order, verify=verify)
    w0, w1, dh, di, sh, si, pn, an = _HEAD[order].unpack_from(buf, start)
    nbytes = w1 & 0x0FFF
    if (
        w0 & 0xFF
        or not LEGAL_OPCODES[w0 >> 8]
        or nbytes > MAX_DATA
        or nbytes + (nbytes & 1) != end - start - MIN_BODY
    ):
        return _decode_body_checked(bytes(buf[start:end]), base, order, verify=verify)
    if big:
        swapped = array("H", buf[start + HEADER_SIZE : end - TRAILER_SIZE])
        swapped.byteswap()
        data = swapped.tobytes()
        if nbytes & 1:
            data = data[:nbytes]
    else:
        data = bytes(buf[start + HEADER_SIZE : start + HEADER_SIZE + nbytes])
    dest, source, checksum = _TRAILER[order].unpack_from(buf, end - TRAILER_SIZE)
    return make_packet(
        w0 >> 8, dh, di, sh, si, pn, an, data, w1 >> 12, make_trailer_value(dest, source, checksum)
    )


def _decode_body_checked(body: bytes, base: int, order: WordOrder, *, verify: bool) -> Packet:
    """:func:`_decode_body` by the book, raising the precise :class:`DecodeError` for a bad frame.

    The checksum is tested first: when it fails, nothing else in the frame can be trusted, and a corrupt
    count or opcode would otherwise be reported as if the sender had meant it.  A sound frame carrying an
    illegal packet raises :class:`IllegalPacketError` (see :mod:`manip.codecs.chaos`).
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

    def data(nbytes: int) -> bytes:
        if order == "<":
            return bytes(body[HEADER_SIZE : HEADER_SIZE + nbytes])
        count = padded_size(nbytes) // 2
        return struct.pack(f"<{count}H", *words[8 : 8 + count])[:nbytes]

    at = WordLocator(base, msb_first=order == ">")
    return checked_packet(words, len(body) - MIN_BODY, data, at, exact=True, trailer=Trailer(*words[-3:]))


def _in_other_order(
    exc: DecodeError, body: Buffer, base: int, order: WordOrder, clause: str, *, verify: bool
) -> DecodeError:
    """``exc``, the error of a frame body read in the link's word ``order``; but when the body decodes with
    its words in the other byte order, an error naming ``clause`` (the link's word order) instead: a
    sender that swaps every word breaks the word order, not the field its swap garbles first."""
    if isinstance(exc, IllegalPacketError):
        return exc
    try:
        _decode_body_checked(bytes(body), base, "<" if order == ">" else ">", verify=verify)
    except DecodeError:
        return exc
    return DecodeError(
        f"the words are sent in the other byte order (read so, the frame decodes): {exc.message}",
        path="frame.word-order",
        offset=base,
        clause=clause,
    )


def _check_body_length(length: int, offset: int, clause: str, what: str, most: int = MAX_BODY) -> None:
    if length & 1 or not MIN_BODY <= length <= most:
        raise DecodeError(
            f"{what} {length} is not an even number from {MIN_BODY} to {most}",
            path="length",
            offset=offset,
            clause=clause,
        )


# ------------------------------------------------------------------------------------ CHUDP


def encode_chudp(p: Packet, *, hw_dest: int | None = None, hw_src: int | None = None) -> bytes:
    """One CHUDP datagram (UDP payload) carrying ``p``; see the module docstring for the layout."""
    return CHUDP_HEADER + _body(p, ">", hw_dest, hw_src)


def decode_chudp(datagram: bytes, *, verify: bool = True, strict: bool = True) -> Packet:
    """Decode one CHUDP datagram; the packet's ``trailer`` is filled in.

    ``verify=False`` skips the checksum test, to look at a corrupt datagram instead of refusing it.  A
    sound datagram holding an illegal packet (opcode, or more than 488 data bytes: the datagram, unlike a
    stream frame, can hold them) raises :class:`IllegalPacketError`; ``strict=False`` returns the packet.
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
    try:
        return _decode_body(datagram, 4, size, 4, ">", verify=verify)
    except IllegalPacketError as exc:
        if strict:
            raise
        return exc.packet
    except DecodeError as exc:
        raise _in_other_order(exc, datagram[4:], 4, ">", "chudp.word-order", verify=verify) from None


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

    def __init__(self, *, verify: bool = True, max_body: int = MAX_BODY) -> None:
        self.verify = verify
        self.max_body = max_body
        """The longest frame body taken (:data:`MAX_BODY`: 488 data bytes; a host without that bound,
        a defect, takes longer ones)."""
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
    def _body_length(self, src: Buffer, pos: int, offset: int) -> int:
        """Validate the frame header at ``src[pos:]`` (stream ``offset``); return the body length."""

    @abstractmethod
    def _decode(self, src: Buffer, start: int, end: int, offset: int) -> Packet:
        """Decode the frame body ``src[start:end]``, found at stream ``offset``."""

    def feed(self, data: bytes) -> list[StreamItem]:
        """Add ``data``; return the packets (or per-frame errors) of every frame now complete, in order."""
        if self._failed is not None:
            raise self._failed
        buf = self._buf
        # Frames are read straight out of ``data`` when nothing is held back (the usual case: a read
        # returns whole frames), so only an incomplete tail is ever copied into the buffer.
        src: Buffer
        if buf:
            buf += data
            src = buf
        else:
            src = data
        size = len(src)
        prefix = self.prefix
        items: list[StreamItem] = []
        pos = 0
        while size - pos >= prefix:
            here = self._start + pos
            try:
                length = self._body_length(src, pos, here)
            except DecodeError as exc:
                self._keep(src, pos)
                self._failed = FrameSyncError(exc.message, exc.path, exc.offset, exc.clause, tuple(items))
                raise self._failed from None
            end = pos + prefix + length
            if size < end:
                break
            try:
                items.append(self._decode(src, pos + prefix, end, here + prefix))
            except DecodeError as exc:
                items.append(exc)
            pos = end
        self._keep(src, pos)
        return items

    def _keep(self, src: Buffer, pos: int) -> None:
        """Hold back ``src[pos:]`` (consumed up to ``pos``) for the next :meth:`feed`."""
        buf = self._buf
        if src is buf:
            del buf[:pos]
        elif pos < len(src):
            buf += src[pos:]
        self._start += pos

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

    def _body_length(self, src: Buffer, pos: int, offset: int) -> int:
        length = src[pos] << 8 | src[pos + 1]
        if length & 1 or not MIN_BODY <= length <= self.max_body:
            _check_body_length(length, offset, self.clause, "frame length", self.max_body)
        return length

    def _decode(self, src: Buffer, start: int, end: int, offset: int) -> Packet:
        try:
            return _decode_body(src, start, end, offset, ">", verify=self.verify)
        except DecodeError as exc:
            raise _in_other_order(exc, src[start:end], offset, ">", self.clause, verify=self.verify) from None


class ChaosdFrameDecoder(StreamDecoder):
    """Decoder for usim's chaosd socket stream; checksums are not verified unless asked (module docstring)."""

    prefix = 4
    clause = "link.chaosd.framing"

    def __init__(self, *, verify: bool = False, max_body: int = MAX_BODY) -> None:
        super().__init__(verify=verify, max_body=max_body)

    def _body_length(self, src: Buffer, pos: int, offset: int) -> int:
        header = bytes(src[pos : pos + 4])
        if header[2:4] != b"\x01\x00":
            raise DecodeError(
                f"chaosd frame header bytes 2-3 are {header[2:4].hex(' ')}, expected 01 00",
                path="frame.header",
                offset=offset + 2,
                clause=self.clause,
            )
        length = header[0] << 8 | header[1]
        _check_body_length(length, offset, self.clause, "chaosd length", self.max_body)
        return length

    def _decode(self, src: Buffer, start: int, end: int, offset: int) -> Packet:
        try:
            return _decode_body(src, start, end, offset, "<", verify=self.verify)
        except DecodeError as exc:
            raise _in_other_order(exc, src[start:end], offset, "<", self.clause, verify=self.verify) from None


def _one_frame(decoder: StreamDecoder, frame: bytes, strict: bool) -> Packet:
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
    return _packet(item, strict)


def _packet(item: StreamItem, strict: bool) -> Packet:
    """The packet of a stream item; raise its error (not for an illegal packet when not ``strict``)."""
    if isinstance(item, DecodeError):
        if strict or not isinstance(item, IllegalPacketError):
            raise item
        return item.packet
    return item


def decode_stream(decoder: StreamDecoder, data: bytes, *, strict: bool = True) -> list[Packet]:
    """All packets of a complete stream capture; the first bad frame (or a cut-off last one) raises.

    ``strict=False`` keeps illegal but sound packets (:class:`IllegalPacketError`) instead."""
    items = decoder.feed(data)
    decoder.finish()
    return [_packet(item, strict) for item in items]


def encode_tcp(p: Packet, *, hw_dest: int | None = None, hw_src: int | None = None) -> bytes:
    """One frame of manip TCP link framing v1 carrying ``p``."""
    frame = _fast_body(p, ">", hw_dest, hw_src, True)
    if frame is None:
        body = _body_checked(p, ">", hw_dest, hw_src)
        return len(body).to_bytes(2, "big") + body
    return frame


def decode_tcp(frame: bytes, *, verify: bool = True, strict: bool = True) -> Packet:
    """Decode a buffer holding exactly one TCP-link frame (``strict`` as for :func:`decode_chudp`; a TCP
    frame cannot hold more than 488 data bytes, so only an illegal opcode can pass)."""
    return _one_frame(TcpFrameDecoder(verify=verify), frame, strict)


def encode_chaosd(p: Packet, *, hw_dest: int | None = None, hw_src: int | None = None) -> bytes:
    """One chaosd socket frame carrying ``p`` (trailer words little-endian like the rest)."""
    return chaosd_frame(_body(p, "<", hw_dest, hw_src))


def chaosd_frame(body: bytes) -> bytes:
    """``body`` (a packet and its trailer) behind the chaosd frame header: its length, high byte first,
    then 01 00."""
    return bytes((len(body) >> 8, len(body) & 0xFF, 1, 0)) + body


def decode_chaosd(frame: bytes, *, verify: bool = False, strict: bool = True) -> Packet:
    """Decode a buffer holding exactly one chaosd frame (checksum checked only with ``verify=True``;
    ``strict`` as for :func:`decode_tcp`)."""
    return _one_frame(ChaosdFrameDecoder(verify=verify), frame, strict)


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
