"""Pure checkers over manip packets: what a client sent, judged against the spec's clauses.

The client's side of :mod:`manip.conformance.judge.checks` (which judges what a server sent): one
request as its client built it (:func:`check_client_request`), and how a client uses the wrist's guards
and gravity model over a whole connection (:func:`check_client_guards`).  No I/O, no clock.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final

from manip.conformance.judge.checks import async_of, required_refusal
from manip.conformance.judge.packets import WirePacket, word
from manip.conformance.judge.violation import Violation
from manip.spec import SPEC
from manip.spec.constants import ERROR_REPLY_OPS, AsyncCondition, ChaosOp, ServerOp
from manip.spec.model import Layout
from manip.spec.notation import octal

__all__ = ["check_client_guards", "check_client_request"]


_MOVE_OPCODES: Final = frozenset(SPEC.request(name).opcode for name in ("move", "straight-move"))


def check_client_request(request: WirePacket) -> list[Violation]:
    """Judge one request as its client built it: a request opcode (0200-0277), and data laid out as the
    opcode's layout says (words, PDP-11 floats, nothing else; a move's 12 floats).  An opcode the spec
    does not define is the server's to refuse (request.unknown-opcode), not a client violation."""
    opcode = request.opcode
    if not ChaosOp.DAT <= opcode < ChaosOp.DWD:
        return [
            Violation.at(
                request,
                "request.opcode-range",
                f"a data packet with opcode {octal(opcode)} is not a request (8-bit data, 0200-0277)",
                expected="a request opcode, 0200-0277",
            )
        ]
    op = SPEC.requests.get(opcode)
    refusal = None if op is None else required_refusal(opcode, request.data)
    if op is None or refusal is None:
        return []
    clause = "move.transform-data" if opcode in _MOVE_OPCODES else "request-data.types"
    return [
        Violation.at(
            request,
            clause,
            f"request #{request.packet_no}: {refusal.reason}",
            expected=f"{op.name} data as its layout says ({_layout_size(op.request)})",
            actual=f"{len(request.data)} data bytes",
        )
    ]


_SET_GUARD: Final = SPEC.request("set-guard").opcode
_CLEAR_GUARD: Final = SPEC.request("clear-guard").opcode
_SET_WEIGHT: Final = SPEC.request("set-weight").opcode
_SET_FRAME_VECTOR: Final = SPEC.request("set-frame-vector").opcode
_NOTIFICATIONS: Final = SPEC.request("request-notifications").opcode
_USES_GRAVITY_MODEL: Final = frozenset(
    SPEC.request(name).opcode for name in ("read-forces", "set-guard", "compliant-move")
)
"""Requests whose effect depends on the gravity-corrected force, hence on the weight set after NEWFV."""
_GUARD_HIT_BIT: Final = 1 << 0


def check_client_guards(packets: Sequence[WirePacket]) -> list[Violation]:
    """Judge how a client uses the wrist's guards and gravity model (B.8, B.9), over a whole connection:
    a new guard gets a number not armed (armed from the moment its set guard is sent; free again once
    clear guard is sent, a guard-hit asynchronous response reports it tripped, or the server answers
    its set guard with an error; reuse is judged only while guard hits are reported, as the client
    cannot know otherwise); neither set weight nor set frame vector while a guard is armed; after set
    frame vector, set weight before the next request that uses the gravity-corrected force."""
    found: list[Violation] = []
    armed: dict[int, WirePacket] = {}
    mask = 0
    frame_changed: WirePacket | None = None
    for p in packets:
        if p.direction == "s2c":
            _server_frees(p, armed)
            continue
        if p.opcode == _NOTIFICATIONS:
            mask = word(p.data, 0) or 0
        elif p.opcode == _CLEAR_GUARD:
            armed.pop((word(p.data, 0) or 0) & 0xF, None)
        elif p.opcode in (_SET_WEIGHT, _SET_FRAME_VECTOR) and armed:
            numbers = ", ".join(str(i) for i in sorted(armed))
            found.append(
                Violation.at(
                    p,
                    "client.no-newwc-with-guard",
                    f"request #{p.packet_no} changes the gravity model while guard(s) {numbers} are armed",
                    expected="set weight and set frame vector only with no guard armed",
                )
            )
        if p.opcode in _USES_GRAVITY_MODEL and frame_changed is not None:
            found.append(
                Violation.at(
                    p,
                    "client.newwc-on-load",
                    f"request #{p.packet_no} relies on the gravity model after set frame vector "
                    f"#{frame_changed.packet_no} with no set weight since",
                    expected="set weight (NEWWC) after every set frame vector, before forces are used",
                )
            )
            frame_changed = None
        if p.opcode == _SET_FRAME_VECTOR:
            frame_changed = p
        elif p.opcode == _SET_WEIGHT:
            frame_changed = None
        elif p.opcode == _SET_GUARD:
            index = (word(p.data, 0) or 0) & 0xF
            earlier = armed.get(index)
            if earlier is not None and mask & _GUARD_HIT_BIT:
                found.append(
                    Violation.at(
                        p,
                        "client.guard-numbers",
                        f"request #{p.packet_no} arms guard {index}, armed by request #{earlier.packet_no} "
                        "and neither cleared nor reported tripped since",
                        expected="a new guard numbered with a guard not in use",
                    )
                )
            armed[index] = p
    return found


def _server_frees(packet: WirePacket, armed: dict[int, WirePacket]) -> None:
    """The guards a server packet frees: the one a guard hit reports tripped, or the one whose set guard
    an error (0201, 0202) answers."""
    hit = async_of(packet) if packet.opcode == ServerOp.ASYNCHRONOUS_RESPONSE else None
    if hit is not None and hit.condition == AsyncCondition.GUARD_HIT:
        armed.pop(hit.word3 & 0xF, None)
    elif packet.opcode in ERROR_REPLY_OPS:
        number = word(packet.data, 0)
        for index, request in list(armed.items()):
            if request.packet_no == number:
                del armed[index]


def _layout_size(layout: Layout) -> str:
    size = layout.fixed_size
    return "no data" if size == 0 else f"{size} bytes" if size is not None else "a variable length"
