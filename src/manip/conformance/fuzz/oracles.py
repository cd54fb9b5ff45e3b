"""What the transcript checks cannot know without the meaning of values, the state of the session, or
what the server said of itself: judged on one connection's packets, in order.

* The state of the arm, by the suite's stateful judge, :class:`~manip.conformance.judge.model.ProtocolModel`,
  fed the connection's requests, answers and asynchronous errors in the order they came (an abort
  reported before an answer happened before its request was served).  Of what the model finds, the
  fuzzer reports :data:`STATEFUL`: **speed.range** (set speed with a factor outside 0 < n <= 1 is a
  command error, never done), **motion.no-power** (after kill power, motion is refused with NAP until
  enable power) and **motion.abort** (after an asynchronous error aborts motion, motion is refused
  with AWA until enable power or reset abort).  The rest of what it finds the transcript checks judge
  already, or needs what a fuzzer cannot know (the arm's limits, which segments finished).
* What describe self said, for the rest of the connection (``describe-self-truthful``):
  **describe.operations-answered** (an opcode listed under ``:operations`` is not refused as unserved:
  C UOP or C UIM), **describe.operations-complete** (an opcode not refused as unserved is listed),
  **describe.dof-joint-vectors** (joint angles and solve forwards reply with ``:degrees-of-freedom``
  floats) and **describe.joint-limits** (set joint angles with a joint beyond a stated limit is not
  accepted).

Each is a :class:`~manip.conformance.judge.violation.Violation` about the answer packet (``packet``),
with the request's bytes.  The packet after an accepted free joint is discarded by the server
(answered done without being executed), so it is judged by none of these.
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Final

from manip.codecs.errors import CodecError
from manip.codecs.lisp import LispValue
from manip.codecs.messages import ErrorReply, decode_error
from manip.codecs.pairing import ReplyPairing
from manip.codecs.pdp11float import unpack_f_array
from manip.conformance.judge.checks import (
    WirePacket,
    describe,
    description_operations,
    multi_text,
    parse_description,
    required_refusal,
    word,
)
from manip.conformance.judge.model import AnswerSummary, ProtocolModel
from manip.conformance.judge.violation import Violation
from manip.spec import SPEC
from manip.spec.constants import ERROR_STRING_OPS, ServerOp
from manip.spec.notation import octal

__all__ = ["STATEFUL", "AnsweredRequest", "answers", "oracle_violations"]

_FREE_JOINT: Final = SPEC.request("free-joint").opcode
_DESCRIBE: Final = SPEC.request("describe-self").opcode
_SET_JOINTS: Final = SPEC.request("set-joint-angles").opcode
_JOINT_REPLIES: Final = frozenset(SPEC.request(name).opcode for name in ("joint-angles", "solve-forwards"))
_REQUESTS: Final = range(0o200, 0o300)
STATEFUL: Final = frozenset({"speed.range", "motion.no-power", "motion.abort"})
"""The clauses of the stateful model's violations the fuzzer reports (module docstring)."""
UNSERVED: Final = ("UOP", "UIM")
"""Error codes saying an opcode is not served (erratum unknown-opcode; UIM: not on this robot)."""


@dataclass(frozen=True)
class AnsweredRequest:
    """A request and the packets that answer it (several for describe self's text)."""

    request: WirePacket
    packets: tuple[WirePacket, ...]

    @property
    def first(self) -> WirePacket:
        return self.packets[0]


def _in_order(packets: Sequence[WirePacket]) -> Iterator[WirePacket | AnsweredRequest]:
    """Requests, asynchronous packets and answered requests, in the order they came (an answer when its
    last packet came), by the shared pairing rule (:mod:`manip.codecs.pairing`: a well-formed describe
    self by its text packets up to the empty one or an error); closes and answers to nothing (the
    initial RESPONSE, which answers the RFC) are left out."""
    pairing: ReplyPairing[WirePacket] = ReplyPairing()
    parts: list[WirePacket] = []
    for p in packets:
        if p.is_close:
            continue
        if p.direction == "c2s":
            pairing.request(p, p.opcode, p.data)
            yield p
            continue
        place = pairing.server(p.opcode, p.data)
        if place.role == "async":
            yield p
        if place.request is None:
            continue
        parts.append(p)
        if place.final:
            yield AnsweredRequest(place.request, tuple(parts))
            parts = []
    if parts and (request := pairing.in_progress) is not None:
        yield AnsweredRequest(request, tuple(parts))


def answers(packets: Sequence[WirePacket]) -> Iterator[AnsweredRequest]:
    """Requests with their answers in order (see :func:`_in_order`)."""
    for item in _in_order(packets):
        if isinstance(item, AnsweredRequest):
            yield item


def _error(packet: WirePacket) -> ErrorReply | None:
    """The decoded error string of an error packet, or None."""
    if packet.opcode not in ERROR_STRING_OPS:
        return None
    aligned: bool | None
    for aligned in (None, False):  # either layout (erratum error-arg-layout), else a bad pad read as numbers
        with contextlib.suppress(CodecError):
            return decode_error(packet.opcode, packet.data, align_args=aligned)
    return None


@dataclass
class _Description:
    operations: frozenset[int] | None
    dof: int | None
    limits: tuple[tuple[float, float], ...] | None


def _number(value: LispValue) -> float | None:
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else None


def _description(answer: AnsweredRequest) -> _Description | None:
    entries, problems = parse_description(multi_text(answer.packets))
    if entries is None or problems:
        return None
    listed = entries.get("operations")
    operations = frozenset(description_operations(entries)) if isinstance(listed, list) else None
    dof_value = entries.get("degrees-of-freedom")
    dof = (
        dof_value
        if isinstance(dof_value, int) and not isinstance(dof_value, bool) and dof_value > 0
        else None
    )
    return _Description(operations, dof, _limits(entries))


def _limits(entries: Mapping[str, LispValue]) -> tuple[tuple[float, float], ...] | None:
    value = entries.get("joint-limits")
    if not isinstance(value, list):
        return None
    out: list[tuple[float, float]] = []
    for pair in value:
        if not isinstance(pair, list) or len(pair) != 2:
            return None
        lower, upper = _number(pair[0]), _number(pair[1])
        if lower is None or upper is None or lower > upper:
            return None
        out.append((lower, upper))
    return tuple(out)


def oracle_violations(packets: Sequence[WirePacket], *, rfc_packet_no: int | None = None) -> list[Violation]:
    """Everything the module docstring lists, in the order the answers came.  ``rfc_packet_no``: the
    RFC's number, which an asynchronous error before any answer carries."""
    out: list[Violation] = []
    model = ProtocolModel()
    if rfc_packet_no is not None:
        model.sent(rfc_packet_no, initial=True)
    discard = False
    said: _Description | None = None
    for item in _in_order(packets):
        if isinstance(item, WirePacket):
            if item.direction == "c2s":
                model.sent(item.packet_no)
            elif item.opcode == ServerOp.ASYNCHRONOUS_ERROR and (error := _error(item)) is not None:
                model.on_async_error(error.request_number, error.error)
            continue
        error = _error(item.first)
        stateful = _stateful(model, item, error)
        if stateful is not None:
            out.append(stateful)
        if discard:  # the packet after free joint: answered done, never executed
            discard = False
            continue
        discard = item.request.opcode == _FREE_JOINT and item.first.opcode == ServerOp.RESPONSE
        if said is not None:
            out += _described(said, item, error)
        request = item.request
        accepted = item.first.opcode == ServerOp.RESPONSE
        if request.opcode == _DESCRIBE and accepted and len(item.packets) > 1 and _well_formed(request):
            said = _description(item) or said
    return out


def _view(answer: WirePacket, error: ErrorReply | None) -> AnswerSummary | None:
    """The model's view of an answer (``error``: its decoded error string); None for an error whose
    string does not decode (the transcript checks' violation)."""
    if answer.opcode == ServerOp.RESPONSE:
        segment = word(answer.data, 2) if len(answer.data) == 4 else None
        return AnswerSummary(True, empty=len(answer.data) == 2, segment=segment)
    return None if error is None else AnswerSummary(False, error=error.error)


def _stateful(model: ProtocolModel, item: AnsweredRequest, error: ErrorReply | None) -> Violation | None:
    """The model's judgement of one answer (the state its earlier answers and asynchronous errors left),
    then its state updated: a violation of :data:`STATEFUL`, or None."""
    request, answer = item.request, item.first
    view = _view(answer, error)
    if view is None:
        return None
    expectation = model.expect(request.opcode, request.data)
    found = model.judge(expectation, view)
    model.observe(request.packet_no, request.opcode, request.data, view)
    if found is None or found.clause not in STATEFUL:
        return None
    op = SPEC.requests.get(request.opcode)
    name = op.name if op is not None else f"opcode {octal(request.opcode)}"
    return replace(found, message=f"{name} was answered {describe(answer)}", data=request.data, packet=answer)


def _described(said: _Description, item: AnsweredRequest, decoded: ErrorReply | None) -> list[Violation]:
    """What describe self said, held against one answer (``decoded``: its error string), module
    docstring."""
    out: list[Violation] = []
    request, answer = item.request, item.first
    opcode = request.opcode
    error = None if decoded is None else (decoded.error.severity, decoded.error.code)
    if opcode not in _REQUESTS or (error is None and answer.opcode != ServerOp.RESPONSE):
        return out  # an error that does not decode is its own violation already
    accepted = answer.opcode == ServerOp.RESPONSE
    add = functools.partial(_add, out, item)
    if said.operations is not None:
        unserved = error is not None and error[1] in UNSERVED
        listed = opcode in said.operations
        code = f" ({error[1]})" if error is not None else ""
        if listed and unserved:
            add(
                "describe.operations-answered",
                f"opcode {octal(opcode)}, listed under :operations, was refused as unserved{code}",
                "the opcode served: describe self lists it",
            )
        elif not listed and not unserved:
            add(
                "describe.operations-complete",
                f"opcode {octal(opcode)} was served but describe self does not list it",
                f"opcode {octal(opcode)} listed under :operations, or refused as unserved (C UOP)",
            )
    if said.dof is not None and opcode in _JOINT_REPLIES and accepted and _well_formed(request):
        floats = (len(answer.data) - 2) // 4
        if floats != said.dof:
            add(
                "describe.dof-joint-vectors",
                f"{SPEC.requests[opcode].name} replied with {floats} joint angles",
                f"{said.dof} joint angles (:degrees-of-freedom {said.dof})",
                f"{len(answer.data) - 2} data bytes after the request number",
            )
    if said.limits is not None and opcode == _SET_JOINTS and accepted and _well_formed(request):
        beyond = _beyond(request.data, said.limits)
        if beyond is not None:
            add(
                "describe.joint-limits",
                f"set joint angles with {beyond} was accepted",
                "JOR: a joint beyond its stated limit",
            )
    return out


def _well_formed(request: WirePacket) -> bool:
    return required_refusal(request.opcode, request.data) is None


def _add(
    out: list[Violation], item: AnsweredRequest, clause: str, message: str, expected: str, actual: str = ""
) -> None:
    shown = actual or describe(item.first)
    out.append(Violation(message, clause, None, expected, shown, item.request.data, packet=item.first))


def _beyond(data: bytes, limits: tuple[tuple[float, float], ...]) -> str | None:
    try:
        joints = [float(x) for x in unpack_f_array(data)]
    except CodecError:
        return None
    for joint, (angle, (lower, upper)) in enumerate(zip(joints, limits, strict=False), start=1):
        if angle < lower - 1e-3 or angle > upper + 1e-3:
            return f"joint {joint} at {angle:g} degrees, beyond its stated limits {lower:g} to {upper:g}"
    return None
