"""What the transcript checks cannot know without the meaning of values, the state of the session, or
what the server said of itself: judged on one connection's packets, in order.

* **speed.range**: set speed with a factor outside 0 < n <= 1 is a command error (C), never done.
* **motion.no-power**: after kill power answered done, a motion request (one answered with a segment
  number) is not accepted until enable power is.
* **motion.abort**: after an asynchronous error saying motion was aborted (COL, PAN), a motion request
  answered after it is not accepted until enable power or reset abort is (motion.reset).
* What describe self said, for the rest of the connection (``describe-self-truthful``):
  **describe.operations-answered** (an opcode listed under ``:operations`` is not refused as unserved:
  C UOP or C UIM), **describe.operations-complete** (an opcode not refused as unserved is listed),
  **describe.dof-joint-vectors** (joint angles and solve forwards reply with ``:degrees-of-freedom``
  floats) and **describe.joint-limits** (set joint angles with a joint beyond a stated limit is not
  accepted).

The packet after an accepted free joint is discarded by the server (answered done without being
executed), so it is judged by none of these.
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Final

from manip.codecs.errors import CodecError
from manip.codecs.lisp import LispValue
from manip.codecs.messages import decode_error
from manip.codecs.pairing import ReplyPairing
from manip.codecs.pdp11float import unpack_f, unpack_f_array
from manip.conformance.judge.checks import (
    WirePacket,
    describe,
    description_operations,
    multi_text,
    parse_description,
    required_refusal,
)
from manip.spec import SPEC
from manip.spec.constants import ServerOp
from manip.spec.notation import octal

__all__ = ["AnsweredRequest", "OracleFinding", "answers", "oracle_findings"]

_ERRORS: Final = frozenset(
    {
        ServerOp.NON_FATAL_ERROR,
        ServerOp.FATAL_ERROR,
        ServerOp.ASYNCHRONOUS_ERROR,
        ServerOp.ASYNCHRONOUS_WARNING,
    }
)
_SET_SPEED: Final = SPEC.request("set-speed").opcode
_KILL_POWER: Final = SPEC.request("kill-power").opcode
_ENABLE_POWER: Final = SPEC.request("enable-power").opcode
_FREE_JOINT: Final = SPEC.request("free-joint").opcode
_DESCRIBE: Final = SPEC.request("describe-self").opcode
_SET_JOINTS: Final = SPEC.request("set-joint-angles").opcode
_JOINT_REPLIES: Final = frozenset(SPEC.request(name).opcode for name in ("joint-angles", "solve-forwards"))
_MOTION: Final = frozenset(op.opcode for op in SPEC.requests.values() if op.response.form == "segment")
_REQUESTS: Final = range(0o200, 0o300)
_RESETS: Final = frozenset(SPEC.request(name).opcode for name in ("enable-power", "reset-abort"))
ABORTS: Final = ("COL", "PAN")
"""Codes of the asynchronous errors that abort motion: collision, panic button (motion.abort)."""
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


@dataclass(frozen=True)
class OracleFinding:
    at: WirePacket
    """The answer packet it is about."""
    request: WirePacket
    clause: str
    message: str
    expected: str
    actual: str


def answers(packets: Sequence[WirePacket]) -> Iterator[AnsweredRequest]:
    """Requests with their answers in order, by the shared pairing rule (:mod:`manip.codecs.pairing`:
    a well-formed describe self by its text packets up to the empty one or an error); closes,
    asynchronous packets and answers to nothing (the initial RESPONSE, which answers the RFC) are no
    answers."""
    pairing: ReplyPairing[WirePacket] = ReplyPairing()
    parts: list[WirePacket] = []
    for p in packets:
        if p.is_close:
            continue
        if p.direction == "c2s":
            pairing.request(p, p.opcode, p.data)
            continue
        place = pairing.server(p.opcode, p.data)
        if place.request is None:
            continue
        parts.append(p)
        if place.final:
            yield AnsweredRequest(place.request, tuple(parts))
            parts = []
    if parts and (request := pairing.in_progress) is not None:
        yield AnsweredRequest(request, tuple(parts))


def _error_code(packet: WirePacket) -> tuple[str, str] | None:
    """(severity, code) of an error packet, or None."""
    if packet.opcode not in _ERRORS:
        return None
    for aligned in (True, False):  # the numbers after the NUL start at an even offset, or should
        with contextlib.suppress(CodecError):
            error = decode_error(packet.opcode, packet.data, align_args=aligned).error
            return error.severity, error.code
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


def oracle_findings(packets: Sequence[WirePacket]) -> list[OracleFinding]:
    """Everything the module docstring lists, in the order the answers came."""
    out: list[OracleFinding] = []
    powered: bool | None = None
    discard = False
    said: _Description | None = None
    aborted_at = _aborts(packets)
    aborted: int | None = None  # position of the abort in force
    position = {id(p): i for i, p in enumerate(packets)}
    for item in answers(packets):
        request, answer = item.request, item.first
        accepted = answer.opcode == ServerOp.RESPONSE
        if discard:  # the packet after free joint: answered done, never executed
            discard = False
            continue
        opcode = request.opcode
        well_formed = required_refusal(opcode, request.data) is None
        error = _error_code(answer)

        add = functools.partial(_add, out, item)

        if opcode == _FREE_JOINT and accepted:
            discard = True
        if opcode == _SET_SPEED and len(request.data) == 4:
            with contextlib.suppress(CodecError):
                factor = unpack_f(request.data)
                if not 0.0 < factor <= 1.0 and (accepted or (error is not None and error[0] != "C")):
                    add(
                        "speed.range",
                        f"set speed {factor:g} was answered {describe(answer)}",
                        "a non-fatal error of severity C: the factor is outside 0 < n <= 1",
                    )
        # The target sends in order: an abort reported before this answer happened before it was served.
        at = position[id(answer)]
        for abort in aborted_at:
            if abort < at and (aborted is None or abort > aborted):
                aborted = abort
        if opcode in _RESETS and accepted:
            aborted_at = [a for a in aborted_at if a > position[id(answer)]]
            aborted = None
        elif opcode in _MOTION and aborted is not None and accepted and well_formed:
            add(
                "motion.abort",
                f"{SPEC.requests[opcode].name} was accepted after motion was aborted, before a reset",
                "a non-fatal error AWA until enable power or reset abort",
            )
        if opcode == _KILL_POWER and accepted:
            powered = False
        elif opcode == _ENABLE_POWER and accepted:
            powered = True
        elif opcode in _MOTION and powered is False and accepted and well_formed:
            add(
                "motion.no-power",
                f"{SPEC.requests[opcode].name} was accepted after kill power answered done",
                "a non-fatal error NAP: arm power is off",
            )
        undecodable = error is None and answer.opcode != ServerOp.RESPONSE  # its own finding already
        if said is not None and opcode in _REQUESTS and not undecodable:
            unserved = error is not None and error[1] in UNSERVED
            if said.operations is not None:
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
            if said.dof is not None and opcode in _JOINT_REPLIES and accepted and well_formed:
                floats = (len(answer.data) - 2) // 4
                if floats != said.dof:
                    add(
                        "describe.dof-joint-vectors",
                        f"{SPEC.requests[opcode].name} replied with {floats} joint angles",
                        f"{said.dof} joint angles (:degrees-of-freedom {said.dof})",
                        f"{len(answer.data) - 2} data bytes after the request number",
                    )
            if said.limits is not None and opcode == _SET_JOINTS and accepted and well_formed:
                beyond = _beyond(request.data, said.limits)
                if beyond is not None:
                    add(
                        "describe.joint-limits",
                        f"set joint angles with {beyond} was accepted",
                        "JOR: a joint beyond its stated limit",
                    )
        if opcode == _DESCRIBE and accepted and well_formed and len(item.packets) > 1:
            said = _description(item) or said
    return out


def _aborts(packets: Sequence[WirePacket]) -> list[int]:
    """Positions of the asynchronous errors that say motion was aborted (a collision, the panic button)."""
    out = []
    for i, p in enumerate(packets):
        if p.direction == "s2c" and p.opcode == ServerOp.ASYNCHRONOUS_ERROR:
            error = _error_code(p)
            if error is not None and error[1] in ABORTS:
                out.append(i)
    return out


def _add(
    out: list[OracleFinding],
    item: AnsweredRequest,
    clause: str,
    message: str,
    expected: str,
    actual: str = "",
) -> None:
    out.append(
        OracleFinding(item.first, item.request, clause, message, expected, actual or describe(item.first))
    )


def _beyond(data: bytes, limits: tuple[tuple[float, float], ...]) -> str | None:
    try:
        joints = [float(x) for x in unpack_f_array(data)]
    except CodecError:
        return None
    for joint, (angle, (lower, upper)) in enumerate(zip(joints, limits, strict=False), start=1):
        if angle < lower - 1e-3 or angle > upper + 1e-3:
            return f"joint {joint} at {angle:g} degrees, beyond its stated limits {lower:g} to {upper:g}"
    return None
