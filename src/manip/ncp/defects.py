"""How a faulty Chaos host departs from the Chaosnet rules: the defects its NCP and its links are given.

The reference server's fault switches of the Chaos level (``manip-server --fault``) reach the NCP and the
links as this one value, :class:`ChaosDefects`, carried by :class:`~manip.ncp.config.NcpConfig`: the NCP
reads its fields where the protocol decides (a LOS to send, a packet to send again, a duplicate RFC to
recognise, a silent peer to give up), the links where they lay out a frame.  The defaults are the rules;
a conforming host never sets a field, and the protocol code never names a fault switch.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["ChaosDefects"]


@dataclass(frozen=True, slots=True)
class ChaosDefects:
    """The Chaos-level defects of one host (the defaults are the rules: no defect)."""

    # ------------------------------------------------------------------ the NCP
    los_unknown_connection: bool = True
    """A packet for a connection that does not exist draws a LOS (clause ``ncp.los``)."""
    los_illegal_opcode: bool = True
    """A packet with an illegal opcode draws a LOS (``chaos.opcode.legal``)."""
    bounds_data: bool = True
    """More than 488 data bytes draw a LOS, and a stream link refuses a frame that long
    (``chaos.data.max-488``)."""
    retransmits: bool = True
    """Unreceipted controlled packets are sent again (``ncp.retransmission``)."""
    recognises_duplicate_rfc: bool = True
    """An RFC from a host and index that already have a connection goes to that connection
    (``ncp.duplicate-rfc``)."""
    gives_up_silent_peer: bool = True
    """A connection whose peer is silent for ``broken_after`` is declared broken (``ncp.broken``)."""
    packet_number_step: int = 1
    """What each controlled packet adds to the packet number (``ncp.packet-numbers``)."""

    # ------------------------------------------------------------------ the frames a link sends
    header_source_first: bool = False
    """The source host and index words come before the destination's in the header
    (``chaos.header.layout``)."""
    header_low_byte: int = 0
    """The byte below the opcode in header word 0 (``chaos.header.unused-byte-zero``)."""
    nbytes_counts_odd_byte: bool = True
    """nbytes counts an odd last data byte (``chaos.header.nbytes``)."""
    data_first_byte_low: bool = True
    """The first data byte of each word is its low byte (``chaos.data.byte-order``)."""
    chudp_header: bool = True
    """A CHUDP datagram starts with 01 01 00 00 (``chudp.header``)."""
    chudp_pads_odd_byte: bool = True
    """An odd last data byte is padded to a whole word on CHUDP (``chudp.length``)."""
    chudp_msb_first: bool = True
    """CHUDP words go most significant byte first (``chudp.word-order``)."""
    trailer_source_own: bool = True
    """The trailer's hardware source is the sender's own address (``chudp.trailer``)."""
    checksum_covers_trailer: bool = True
    """The checksum covers the trailer's destination and source words (``chudp.checksum``)."""
    tcp_length_counts_pad: bool = True
    """The TCP link's frame length counts the pad byte after an odd last data byte (``link.tcp.framing``)."""
    chaosd_little_endian: bool = True
    """The chaosd socket's words go low byte first (``link.chaosd.framing``)."""

    @property
    def frames_by_the_rules(self) -> bool:
        """Whether every frame is laid out by the rules (a link then uses the codec's own encoders)."""
        return all(getattr(self, f) == getattr(_RULES, f) for f in FRAME_FIELDS)


_RULES = ChaosDefects()
FRAME_FIELDS = (
    "header_source_first",
    "header_low_byte",
    "nbytes_counts_odd_byte",
    "data_first_byte_low",
    "chudp_header",
    "chudp_pads_odd_byte",
    "chudp_msb_first",
    "trailer_source_own",
    "checksum_covers_trailer",
    "tcp_length_counts_pad",
    "chaosd_little_endian",
)
"""The fields that change how a link lays out a frame (the rest change what the NCP does)."""
