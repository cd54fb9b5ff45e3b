"""Frames laid out with a host's Chaos-level defects (manip.links.defective): with none, the very frames
the codec's encoders write; with each, a frame the receiving link refuses for the rule it breaks."""

from __future__ import annotations

from collections.abc import Callable

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from manip.codecs import framing
from manip.codecs.errors import DecodeError
from manip.codecs.packet import MAX_DATA, Packet
from manip.links.defective import defective_frame
from manip.ncp.defects import FRAME_FIELDS, ChaosDefects
from manip.spec.constants import ServerOp

ENCODERS: dict[str, Callable[..., bytes]] = {
    "tcp": framing.encode_tcp,
    "chudp": framing.encode_chudp,
    "chaosd": framing.encode_chaosd,
}
DECODERS: dict[str, Callable[..., Packet]] = {
    "tcp": framing.decode_tcp,
    "chudp": framing.decode_chudp,
    "chaosd": lambda frame: framing.decode_chaosd(frame, verify=True),
}
ODD = Packet(ServerOp.RESPONSE, 0o401, 0x0A01, 0o440, 0x5E02, 7, 3, b"odd")
"""A reply with an odd number of data bytes (every framing defect shows on it)."""

words = st.integers(0, 0xFFFF)
packets = st.builds(
    Packet,
    st.sampled_from([0o200, 0o201, 0o203, 0o7, 0o5]),
    words,
    words,
    words,
    words,
    words,
    words,
    st.binary(max_size=MAX_DATA),
)


@settings(max_examples=25)
@given(packets, st.sampled_from(sorted(ENCODERS)))
def test_without_defects_the_frames_are_the_codecs(packet: Packet, kind: str) -> None:
    assert ChaosDefects().frames_by_the_rules
    frame = defective_frame(kind, packet, 0o440, 0o401, ChaosDefects())
    assert frame == ENCODERS[kind](packet, hw_dest=0o440, hw_src=0o401)


@pytest.mark.parametrize(
    ("kind", "defect", "clause"),
    [
        ("tcp", {"header_low_byte": 1}, "chaos.header.unused-byte-zero"),
        ("tcp", {"nbytes_counts_odd_byte": False}, "chaos.header.nbytes"),
        ("tcp", {"tcp_length_counts_pad": False}, "link.tcp.framing"),
        ("tcp", {"checksum_covers_trailer": False}, "chudp.checksum"),
        ("chudp", {"chudp_header": False}, "chudp.header"),
        ("chudp", {"chudp_pads_odd_byte": False}, "chudp.length"),
        ("chudp", {"chudp_msb_first": False}, "chudp.word-order"),
        ("chudp", {"checksum_covers_trailer": False}, "chudp.checksum"),
        ("chaosd", {"chaosd_little_endian": False}, "link.chaosd.framing"),
    ],
)
def test_each_framing_defect_breaks_its_rule(kind: str, defect: dict[str, object], clause: str) -> None:
    defects = ChaosDefects(**defect)  # type: ignore[arg-type]
    assert not defects.frames_by_the_rules
    frame = defective_frame(kind, ODD, 0o401, 0o440, defects)
    with pytest.raises(DecodeError) as raised:
        DECODERS[kind](frame)
    assert raised.value.clause == clause, raised.value


@pytest.mark.parametrize(
    ("defect", "shows"),
    [
        ({"data_first_byte_low": False}, lambda p: p.data == b"do\0"),
        ({"trailer_source_own": False}, lambda p: p.trailer.source == 0o401),
        ({"header_source_first": True}, lambda p: (p.src_host, p.dest_host) == (0o401, 0o440)),
    ],
)
def test_the_defects_a_frame_cannot_show_leave_it_sound(
    defect: dict[str, object], shows: Callable[[Packet], bool]
) -> None:
    """Swapped data bytes, a trailer naming the next hop as the source and the header's addresses in the
    wrong order make sound frames: the receiver sees them in what they carry (the link and frames cases)."""
    defects = ChaosDefects(**defect)  # type: ignore[arg-type]
    packet = framing.decode_chudp(defective_frame("chudp", ODD, 0o401, 0o440, defects))
    assert shows(packet), packet
    assert not shows(framing.decode_chudp(defective_frame("chudp", ODD, 0o401, 0o440, ChaosDefects())))


def test_the_frame_fields_are_the_links() -> None:
    """FRAME_FIELDS names every field a link reads; the others are the NCP's."""
    for name in FRAME_FIELDS:
        assert not ChaosDefects(**{name: not getattr(ChaosDefects(), name)}).frames_by_the_rules  # type: ignore[arg-type]
    ncp_only = ChaosDefects(retransmits=False, los_unknown_connection=False, packet_number_step=2)
    assert ncp_only.frames_by_the_rules
