"""The diff's scenarios of the Chaos level: what the server's NCP and link must do with packets a
well-behaved client never sends (the NCP cases' packets, sent by hand).

A packet for a connection that does not exist and one with an illegal opcode each draw a LOS back to
the sender (clauses ``ncp.los``, ``chaos.opcode.legal``): the fuzzer's judges know the LOS is due (a
:class:`~manip.conformance.fuzz.steps.Stray` says so).  A packet with more than 488 data bytes on the
connection is not served (``chaos.data.max-488``): the server may answer it with a LOS or drop the link
whose framing it breaks, but an answer to it is a breach, which this module's check names.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Final

from manip.codecs.packet import MAX_DATA, Packet
from manip.codecs.pdp11float import pack_f
from manip.conformance.cases.server.ncp import RETRANSMIT_BOUND
from manip.conformance.diff.scenarios.kit import (
    Events,
    description_at,
    req,
    scenario_stream,
    sighting,
    swap_word_bytes,
)
from manip.conformance.diff.streams import Stream
from manip.conformance.fuzz.generators import stray_index
from manip.conformance.fuzz.judge import Sighting
from manip.conformance.fuzz.steps import ConnPacket, Pause, RequestStep, Step, Stray
from manip.spec import SPEC
from manip.spec.constants import ANSWER_OPS, ChaosOp

NOWHERE: Final = 0o123456
"""The destination index of the stray packets: no connection of the server's (the batch picks another
should the server's connection have it)."""
ILLEGAL_OPCODE: Final = 0o77
"""An opcode between the control opcodes (001-016) and the data opcodes (0200-0377)."""
OVERSIZE: Final = MAX_DATA + 2
"""Data bytes of the oversize packet: a word more than a packet may carry."""
ANSWER_WAIT: Final = 0.5
"""Seconds the oversize scenario waits for an answer it must not get."""


def _strays() -> Stream:
    """A data packet to a connection that does not exist, then a packet with an illegal opcode: each must
    draw a LOS back to the index it came from."""
    dat = Packet(ChaosOp.DAT, 0, NOWHERE, 0, stray_index(0, 0), 0, 0, b"manip")
    illegal = Packet(ILLEGAL_OPCODE, 0, NOWHERE, 0, stray_index(1, 0), 0, 0, b"manip")
    groups = [
        ("a data packet to no connection", [Stray(dat, "los", "ncp.los")]),
        ("a packet with an illegal opcode", [Stray(illegal, "los", "chaos.opcode.legal")]),
    ]
    return scenario_stream("stray-packets", groups)


def _not_served(events: Events) -> list[Sighting]:
    """Any answer to the oversize packet (its input has no request of its own) is the packet served."""
    served = [e for e in events.get(1, []) if e.kind == "packet" and e.opcode in ANSWER_OPS]
    return [
        sighting(
            1,
            "chaos.data.max-488",
            f"a packet of {OVERSIZE} data bytes was served",
            "the packet refused (a LOS, or the link dropped), never answered",
            e,
        )
        for e in served[:1]
    ]


def _oversize() -> Stream:
    """Here (its answer waited for: a server that drops the link for the oversize frame drops what it
    had still to send), then a Here of :data:`OVERSIZE` data bytes numbered as the connection's next
    packet (sent as it is: the codec refuses to frame it), which must not be served."""
    here = req("here")
    oversize = ConnPacket("behind", here.opcode, bytes(OVERSIZE), offset=0, clause="chaos.data.max-488")
    groups: list[tuple[str, list[Step]]] = [
        ("here", [here, Pause(ANSWER_WAIT)]),
        ("a here of more than 488 data bytes", [oversize, Pause(ANSWER_WAIT)]),
    ]
    return scenario_stream("oversize", groups, _not_served)


def _duplicate_rfc() -> Stream:
    """Here, the connection's own RFC again (same index and number, as a retransmission is), then Here
    again: the RFC is matched to the open connection (answered with nothing or its OPN again, which the
    fuzzer's judges hold as a :class:`~manip.conformance.fuzz.steps.ConnPacket` ``rfc``'s due), never
    refused or opened as a second connection from another index, and the connection goes on serving."""
    again = ConnPacket("rfc", ChaosOp.RFC, clause="ncp.duplicate-rfc")
    groups: list[tuple[str, list[Step]]] = [
        ("here", [req("here"), Pause(ANSWER_WAIT)]),
        ("the connection's RFC again", [again, Pause(ANSWER_WAIT)]),
        ("here on the connection", [req("here")]),
    ]
    return scenario_stream("duplicate-rfc", groups)


def _swapped_text(data: bytes) -> bytes:
    """``data`` with the two bytes of each whole word swapped, without the zero byte that padded an odd
    length (swapped to the front of the last word)."""
    return swap_word_bytes(data).rstrip(b"\0")


def _text_byte_order(events: Events) -> list[Sighting]:
    """Describe self's text that reads as a description only with the bytes of each word swapped: the
    data went out first byte high (``chaos.data.byte-order``)."""
    if description_at(events, 0) is not None:
        return []
    swapped = {
        0: [replace(e, data=_swapped_text(e.data)) if e.kind == "packet" else e for e in events.get(0, [])]
    }
    if description_at(swapped, 0) is None:
        return []
    first = next(e for e in events[0] if e.kind == "packet")
    return [
        sighting(
            0,
            "chaos.data.byte-order",
            "describe self's text reads as a description only with the two bytes of each word swapped",
            "each word's first byte in its low byte",
            first,
        )
    ]


def _frames() -> Stream:
    """Every shape of server packet, as the link frames cases exchange them: describe self (text over
    several packets), Here (data), set speed (a done), an unassigned opcode (an error string, whose text
    may leave an odd byte).  What their frames break on the side's link the fuzzer's judges name (a frame
    that does not decode, by the link's clause); the data's byte order this module's check reads from
    describe self's text."""
    unassigned = next(code for code in range(0o200, 0o400) if code not in SPEC.requests)
    groups: list[tuple[str, list[Step]]] = [
        ("describe self", [req("describe-self")]),
        ("here", [req("here")]),
        ("set speed 1.0", [req("set-speed", pack_f(1.0))]),
        (f"the unassigned opcode 0{unassigned:o}", [RequestStep(unassigned, b"")]),
    ]
    return scenario_stream("frames", groups, _text_byte_order)


def _lost_answer() -> Stream:
    """Here (its answer waited for), Here with its answer lost on its way (dropped unreceipted) and the
    time server.ncp.retransmission allows for it to come again, then Here again: the lost packet must come
    again, as every controlled packet does until a receipt covers it."""
    lose = ConnPacket("lose", 0, clause="ncp.retransmission")
    groups: list[tuple[str, list[Step]]] = [
        ("here", [req("here"), Pause(ANSWER_WAIT)]),
        ("here, its answer lost", [lose, req("here"), Pause(RETRANSMIT_BOUND)]),
        ("here", [req("here")]),
    ]
    return scenario_stream("lost-answer", groups)


SCENARIOS: Final[dict[str, Callable[[], Stream]]] = {
    "frames": _frames,
    "stray-packets": _strays,
    "oversize": _oversize,
    "duplicate-rfc": _duplicate_rfc,
    "lost-answer": _lost_answer,
}
"""This module's scenarios by name, in the order a diff sends them."""
