"""The Chaos packet in its canonical byte form, "PDP-11 memory order", and the checks every link shares.

The canonical form is how a PDP-11 (or usim's CADR) holds a packet in memory: eight little-endian 16-bit
header words, then the data bytes in natural order, padded with one zero byte to a whole word when
``nbytes`` is odd.  Word 0 is ``opcode << 8`` (its low byte, the first byte in memory, must be zero); word 1
is ``fc << 12 | nbytes``; then destination host and index, source host and index, packet number and ack
number.  Because the first data byte is the *low* byte of its word (clause ``chaos.data.byte-order``), data
word ``k`` is ``d[2k] | d[2k+1] << 8``: :func:`packet_words` gives those logical word values, which is what
the checksum and the other links (:mod:`manip.codecs.framing`) work from.

The layout is written once as a construct ``Struct`` (:data:`PACKET`, and :data:`HEADER` for header-only
parsing; both compile, see :func:`compiled_packet`).  :func:`encode_raw` and :func:`decode_raw` do the same
job with ``struct`` because they sit on every packet's path and are several times faster that way; a test
checks that they and the construct definition agree.  What construct cannot say well (which clause a bad
packet breaks, at which byte) is done by :func:`check_header` and :func:`check_data_length`, which the
framings reuse with their own byte offsets via :class:`WordLocator`.

Garbled versus illegal (erratum ``illegal-packet-delivery``).  A receiver treats two kinds of bad packet
differently.  A *garbled* one (short, lengths that disagree, a bad checksum, the unused header byte set)
cannot be trusted at all and is counted and dropped.  An *illegal* one is sound as a frame (its framing,
checksum and lengths all check out) but breaks a protocol rule that a receiving NCP answers with LOS: an
illegal opcode (clause ``chaos.opcode.legal``) or more than 488 data bytes (``chaos.data.max-488``).  The
strict decoders raise the same :class:`DecodeError` for both, with the same message, path, offset and
clause as always; for an illegal packet the error is an :class:`IllegalPacketError` that also carries the
decoded packet, so a link can hand it to its NCP.  ``strict=False`` returns that packet instead.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from functools import cache
from typing import Any, Final

from construct import AdaptationError, Adapter, Bytes, Container, Int16ul, Padding, Struct, this

from manip.codecs.errors import DecodeError, EncodeError
from manip.codecs.packet import MAX_DATA, Packet, Trailer, make_packet

HEADER_SIZE: Final = 16
"""Bytes in the eight header words."""
TRAILER_SIZE: Final = 6
"""Bytes in the hardware trailer (destination, source, checksum) on links that carry one."""

_HEADER_WORDS = struct.Struct("<8H")


# ------------------------------------------------------------------------------------ construct form


class WordFields(Adapter):  # type: ignore[misc]  # construct is untyped
    """Split one 16-bit word into named bit fields, the first-named field in the most significant bits.

    Chaos header words pack two fields into one word (opcode/unused, fc/nbytes), and ``BitStruct`` would
    read them in byte order, which is wrong for a little-endian word; shifting and masking the whole word
    is both right and compilable (``_emitparse``/``_emitbuild`` inline it into ``Struct.compile()``).
    """

    def __init__(self, subcon: Any, *fields: tuple[str, int]) -> None:
        super().__init__(subcon)
        total = 8 * subcon.sizeof()
        if sum(width for _, width in fields) != total:
            raise ValueError(f"fields {fields} do not fill {total} bits")
        shifts: list[tuple[str, int, int]] = []
        shift = total
        for name, width in fields:
            shift -= width
            shifts.append((name, shift, (1 << width) - 1))
        self.shifts = tuple(shifts)

    def _decode(self, obj: int, context: Any, path: str) -> Container:
        return Container({name: (obj >> shift) & mask for name, shift, mask in self.shifts})

    def _encode(self, obj: Any, context: Any, path: str) -> int:
        word = 0
        for name, shift, mask in self.shifts:
            value = obj[name]
            if not 0 <= value <= mask:
                raise AdaptationError(f"field {name}={value} does not fit in {mask.bit_length()} bits", path)
            word |= value << shift
        return word

    def _emitparse(self, code: Any) -> str:
        parts = ", ".join(f"{name}=(_w >> {shift}) & {mask}" for name, shift, mask in self.shifts)
        return f"reuse({self.subcon._compileparse(code)}, lambda _w: Container({parts}))"

    def _emitbuild(self, code: Any) -> str:
        word = " | ".join(f"((obj[{name!r}] & {mask}) << {shift})" for name, shift, mask in self.shifts)
        return f"(reuse({word}, lambda obj: {self.subcon._compilebuild(code)}), obj)[1]"


HEADER: Final[Any] = Struct(
    "op" / WordFields(Int16ul, ("opcode", 8), ("unused", 8)),
    "count" / WordFields(Int16ul, ("fc", 4), ("nbytes", 12)),
    "dest_host" / Int16ul,
    "dest_index" / Int16ul,
    "src_host" / Int16ul,
    "src_index" / Int16ul,
    "packet_no" / Int16ul,
    "ack_no" / Int16ul,
)
"""The eight header words in PDP-11 memory order (16 bytes)."""

PACKET: Final[Any] = Struct(
    "header" / HEADER,
    "data" / Bytes(this.header.count.nbytes),
    "pad" / Padding(this.header.count.nbytes % 2),
)
"""A whole canonical packet: header, data, and the pad byte when ``nbytes`` is odd."""


# ------------------------------------------------------------------------------------ words and sums


def is_legal_opcode(opcode: int) -> bool:
    """True for 001-016 and 0200-0377, the opcodes a Chaos node accepts (clause ``chaos.opcode.legal``)."""
    return 0o1 <= opcode <= 0o16 or 0o200 <= opcode <= 0o377


LEGAL_OPCODES: Final = tuple(is_legal_opcode(op) for op in range(256))
"""``LEGAL_OPCODES[op]`` is :func:`is_legal_opcode` of ``op`` for every byte, for decoders' hot paths."""


def padded_size(nbytes: int) -> int:
    """Bytes the data occupy on a word-oriented link: ``nbytes`` rounded up to a whole word."""
    return nbytes + (nbytes & 1)


def _fold(total: int) -> int:
    while total >> 16:
        total = (total & 0xFFFF) + (total >> 16)
    return total


def chaos_checksum(words: Iterable[int]) -> int:
    """RFC 1071 ones'-complement checksum of 16-bit words, as CHUDP puts in the trailer.

    Summing first and folding the carries back in afterwards gives the same result as folding after each
    addition (RFC 1071 section 2), and is much faster in Python.
    """
    return ~_fold(sum(words)) & 0xFFFF


def checksum_ok(words: Iterable[int]) -> bool:
    """True when header, data and the whole trailer (checksum included) sum to 0xFFFF.

    This is the receivers' test (klh10, simh); it accepts either ones'-complement zero as the checksum.
    """
    return _fold(sum(words)) == 0xFFFF


def header_words(p: Packet) -> list[int]:
    """The eight logical header words of ``p`` (no range checks; see :func:`check_encodable`)."""
    return [
        p.opcode << 8,
        p.fc << 12 | len(p.data),
        p.dest_host,
        p.dest_index,
        p.src_host,
        p.src_index,
        p.packet_no,
        p.ack_no,
    ]


def data_words(data: bytes) -> list[int]:
    """The data as logical words, first byte low (clause ``chaos.data.byte-order``), odd tail padded."""
    if len(data) & 1:
        data = data + b"\0"
    return list(struct.unpack(f"<{len(data) // 2}H", data))


def packet_words(p: Packet) -> list[int]:
    """Header and padded data as logical 16-bit words, the values every link serializes and sums."""
    return header_words(p) + data_words(p.data)


def make_trailer(p: Packet, hw_dest: int | None = None, hw_src: int | None = None) -> Trailer:
    """The trailer for sending ``p`` over one hop: next-hop and own address default to the packet's.

    The checksum covers the header, padded data, and trailer destination and source (clause
    ``chudp.checksum``).  ``p.trailer`` is ignored on purpose: a trailer belongs to a hop, not a packet.
    """
    dest = p.dest_host if hw_dest is None else hw_dest
    source = p.src_host if hw_src is None else hw_src
    _check_range("trailer.dest", dest, 0xFFFF)
    _check_range("trailer.source", source, 0xFFFF)
    return Trailer(dest, source, chaos_checksum([*packet_words(p), dest, source]))


# ------------------------------------------------------------------------------------ checks


def _check_range(path: str, value: int, top: int) -> None:
    if not isinstance(value, int) or not 0 <= value <= top:
        raise EncodeError(
            f"{path}={value!r} does not fit in {top.bit_length()} bits",
            path=path,
            clause="chaos.header.layout",
        )


def check_encodable(p: Packet) -> None:
    """Raise :class:`EncodeError` naming the field if ``p`` cannot be put on any link.

    Opcode *legality* is not checked, so conformance tests can send an illegal opcode on purpose; only
    that it fits in its byte.
    """
    _check_range("opcode", p.opcode, 0xFF)
    _check_range("fc", p.fc, 0xF)
    for name in ("dest_host", "dest_index", "src_host", "src_index", "packet_no", "ack_no"):
        _check_range(name, getattr(p, name), 0xFFFF)
    if len(p.data) > MAX_DATA:
        raise EncodeError(
            f"{len(p.data)} data bytes; a Chaos packet holds at most {MAX_DATA}",
            path="data",
            clause="chaos.data.max-488",
        )


@dataclass(frozen=True, slots=True)
class WordLocator:
    """Where header word ``i`` (and its high or low byte) sits in the input being decoded.

    Each link stores the same words at a different place and in a different byte order; errors must point
    at the byte the user sees, so the shared checks ask this object for offsets.
    """

    base: int = 0
    msb_first: bool = False

    def word(self, i: int) -> int:
        return self.base + 2 * i

    def high_byte(self, i: int) -> int:
        return self.word(i) + (0 if self.msb_first else 1)

    def low_byte(self, i: int) -> int:
        return self.word(i) + (1 if self.msb_first else 0)


CANONICAL: Final = WordLocator()
"""Offsets in the canonical (raw) form: words little-endian from byte 0."""


@dataclass(eq=False)
class IllegalPacketError(DecodeError):
    """A packet that is sound as a frame but illegal: an illegal opcode, or more than 488 data bytes.

    Message, path, offset and clause are those of the plain :class:`DecodeError` a strict decode has
    always raised for it (so callers that only show errors see no difference); ``packet`` is the packet
    as decoded, data and trailer included, for a receiver whose NCP answers it with LOS.
    """

    packet: Packet = field(kw_only=True)

    def at(self, path: str, offset: int | None = None) -> IllegalPacketError:
        moved = DecodeError(self.message, self.path, self.offset, self.clause).at(path, offset)
        return IllegalPacketError(moved.message, moved.path, moved.offset, moved.clause, packet=self.packet)


def check_header_split(word0: int, word1: int, at: WordLocator = CANONICAL) -> tuple[int, DecodeError | None]:
    """The header checks, split by what a receiver does about them; return ``(nbytes, problem)``.

    A set unused byte means the header is garbled: :class:`DecodeError` is raised.  An illegal opcode or
    a count over 488 is returned as ``problem`` (opcode first), because a receiver answers those with LOS
    once the framing has shown the rest of the packet to be sound.
    """
    if word0 & 0xFF:
        raise DecodeError(
            f"low byte of header word 0 is {word0 & 0xFF:#04x}, must be 0",
            path="header.unused",
            offset=at.low_byte(0),
            clause="chaos.header.unused-byte-zero",
        )
    opcode = word0 >> 8
    nbytes = word1 & 0x0FFF
    if not is_legal_opcode(opcode):
        return nbytes, DecodeError(
            f"opcode 0{opcode:o} is not a Chaos opcode (001-016, 0200-0377)",
            path="header.opcode",
            offset=at.high_byte(0),
            clause="chaos.opcode.legal",
        )
    if nbytes > MAX_DATA:
        return nbytes, DecodeError(
            f"nbytes is {nbytes}; a Chaos packet holds at most {MAX_DATA}",
            path="header.nbytes",
            offset=at.word(1),
            clause="chaos.data.max-488",
        )
    return nbytes, None


def check_header(word0: int, word1: int, at: WordLocator = CANONICAL) -> int:
    """Apply the header checks every link shares; return ``nbytes``.

    Order: the unused byte, the opcode, then the 488-byte limit, so a corrupt count is reported as such
    before any length comparison a framing makes afterwards.
    """
    nbytes, problem = check_header_split(word0, word1, at)
    if problem is not None:
        raise problem
    return nbytes


def check_data_length(nbytes: int, present: int, at: WordLocator = CANONICAL, *, exact: bool) -> None:
    """Compare ``nbytes`` with the data bytes a framing found (``present`` counts any pad byte).

    With ``exact`` the framing fixes the packet's end (CHUDP, TCP, chaosd), so the data must be exactly
    the padded size; otherwise (raw) the data may stop at ``nbytes`` or at the pad byte.
    """
    padded = padded_size(nbytes)
    if present < nbytes or (exact and present < padded):
        need = padded if exact else nbytes
        raise DecodeError(
            f"nbytes is {nbytes} ({need} bytes with padding) but only {present} data bytes are present",
            path="header.nbytes",
            offset=at.word(1),
            clause="chaos.header.nbytes",
        )
    if present > padded:
        raise DecodeError(
            f"nbytes is {nbytes} but {present - padded} more bytes follow the padded data",
            path="header.nbytes",
            offset=at.word(1),
            clause="chaos.header.nbytes",
        )


def packet_from_words(words: Sequence[int], data: bytes, trailer: Trailer | None = None) -> Packet:
    """Build a :class:`Packet` from eight already-checked header words and the (unpadded) data."""
    w0, w1, dest_host, dest_index, src_host, src_index, packet_no, ack_no = words
    return make_packet(
        w0 >> 8, dest_host, dest_index, src_host, src_index, packet_no, ack_no, data, w1 >> 12, trailer
    )


def checked_packet(
    words: Sequence[int],
    data_present: int,
    data: Callable[[int], bytes],
    at: WordLocator,
    *,
    exact: bool,
    trailer: Trailer | None = None,
) -> Packet:
    """The slow, precise decode shared by every framing, once the framing itself has been checked.

    ``words`` starts with the eight header words, ``data_present`` counts the data bytes the framing
    found and ``data(nbytes)`` extracts them.  A garbled header or inconsistent lengths raise
    :class:`DecodeError`; an otherwise sound illegal packet raises :class:`IllegalPacketError` with the
    packet.  Error order is the strict one: header problems before length problems.
    """
    nbytes, problem = check_header_split(words[0], words[1], at)
    try:
        check_data_length(nbytes, data_present, at, exact=exact)
    except DecodeError:
        if problem is not None:
            raise problem from None  # illegal and garbled: the header error, as strict decoding says
        raise
    packet = packet_from_words(words[:8], data(nbytes), trailer)
    if problem is not None:
        raise IllegalPacketError(problem.message, problem.path, problem.offset, problem.clause, packet=packet)
    return packet


# ------------------------------------------------------------------------------------ raw codec


def _short_header(b: bytes, at: WordLocator = CANONICAL) -> DecodeError:
    return DecodeError(
        f"{len(b) - at.base} bytes is shorter than the {HEADER_SIZE}-byte Chaos header",
        path="header",
        offset=len(b),
        clause="chaos.header.layout",
    )


def encode_raw(p: Packet) -> bytes:
    """``p`` in canonical PDP-11 memory order, without a trailer."""
    data = p.data
    n = len(data)
    opcode, fc = p.opcode, p.fc
    dh, di, sh, si, pn, an = p.dest_host, p.dest_index, p.src_host, p.src_index, p.packet_no, p.ack_no
    # The common case: ints (as check_encodable takes them) and bytes, packed at once: struct checks the
    # 16-bit ranges, and a shifted opcode or fc out of range fails there too.  Anything else is checked
    # field by field, for the precise error.
    if (
        n <= MAX_DATA
        and type(data) is bytes
        and isinstance(opcode, int)
        and isinstance(fc, int)
        and isinstance(dh, int)
        and isinstance(di, int)
        and isinstance(sh, int)
        and isinstance(si, int)
        and isinstance(pn, int)
        and isinstance(an, int)
    ):
        try:
            head = _HEADER_WORDS.pack(opcode << 8, fc << 12 | n, dh, di, sh, si, pn, an)
        except struct.error:
            pass
        else:
            return head + data + b"\0" if n & 1 else head + data
    check_encodable(p)
    pad = b"\0" if len(p.data) & 1 else b""
    return _HEADER_WORDS.pack(*header_words(p)) + bytes(p.data) + pad


def decode_raw(b: bytes, *, strict: bool = True) -> Packet:
    """Decode one canonical packet (no trailer); the input must end after the data or its pad byte.

    A missing pad byte after odd data is tolerated (nothing is lost without it); anything after the pad
    byte is an error, because in this form nothing else says where the packet ends.  An illegal but
    otherwise sound packet raises :class:`IllegalPacketError`, or with ``strict=False`` is returned.
    """
    if len(b) < HEADER_SIZE:
        raise _short_header(b)
    w0, w1, dh, di, sh, si, pn, an = _HEADER_WORDS.unpack_from(b)
    nbytes = w1 & 0x0FFF
    present = len(b) - HEADER_SIZE
    if (
        w0 & 0xFF
        or not LEGAL_OPCODES[w0 >> 8]
        or nbytes > MAX_DATA
        or not nbytes <= present <= nbytes + (nbytes & 1)
    ):
        # Something is wrong: let the shared checks say exactly what.
        try:
            return checked_packet(
                _HEADER_WORDS.unpack_from(b),
                present,
                lambda n: bytes(b[HEADER_SIZE : HEADER_SIZE + n]),
                CANONICAL,
                exact=False,
            )
        except IllegalPacketError as exc:
            if strict:
                raise
            return exc.packet
    return make_packet(
        w0 >> 8, dh, di, sh, si, pn, an, bytes(b[HEADER_SIZE : HEADER_SIZE + nbytes]), w1 >> 12
    )


@cache
def compiled_packet() -> Any:
    """:data:`PACKET` compiled (done once, on first use), for bulk tools that want construct containers."""
    return PACKET.compile()


@cache
def compiled_header() -> Any:
    """:data:`HEADER` compiled (done once, on first use)."""
    return HEADER.compile()


def parse_header(b: bytes) -> Any:
    """The header fields of a canonical packet as a construct ``Container``; only the length is checked."""
    if len(b) < HEADER_SIZE:
        raise _short_header(b)
    return compiled_header().parse(b[:HEADER_SIZE])
