"""The diff's scenarios: the directed cases' request sequences as streams, each with the judge that
knows what its answers must be.

The fuzzer's generated inputs seldom reach a condition a directed case arranges on purpose: a motion
read back after it ends, describe self followed by a probe of every opcode it lists, a fatal error.
A scenario is such a request sequence (:class:`~manip.conformance.diff.streams.Stream` with a
``scenario`` name), sent to both sides from the same start like every stream, and judged by the
fuzzer's judges plus its own :data:`~manip.conformance.diff.streams.ScenarioCheck`: a check that
knows what the requests it sent demand of the answers (the joint angles a set joint angles put the
arm at, the ready position describe self stated, the joints a calibration failure names).  A breach
its check finds is a :class:`~manip.conformance.fuzz.judge.Sighting` like any judge's, so a
difference on that input is a violation (class a) naming the clause.  A scenario about what a
connection leaves behind closes its connection and goes on on the next
(:class:`~manip.conformance.fuzz.steps.Reconnect`); one about how the arm moves reads the joints or the
hand midway through a move, a fixed time after it was answered (the same time on both sides, in virtual
time on an embedded one).

Some scenarios need a condition of the arm's world (``conditions``: the world contract's
:class:`~manip.conformance.suite.world.Condition`, as the directed cases arrange them): an embedded
side's world arranges them at once; an addressed side's through its ``--world-a/-b`` (contract 2).  A
side whose world cannot arrange one, or that has none, is not sent the scenario (the report says
so).  Sans-I/O.
"""

from __future__ import annotations

import contextlib
import math
import struct
from collections.abc import Callable, Sequence
from typing import Final

from manip.arm.kinematics import PUMA600, configuration, forward
from manip.codecs.error_string import parse_error
from manip.codecs.errors import CodecError
from manip.codecs.lispm_text import decode_lispm
from manip.codecs.pdp11float import pack_f, unpack_f
from manip.conformance.cases.server.motion import CONFIGURATION_SEED, HAND_TOL_MM, SPEED_MATCH, TURN_TOL_DEG
from manip.conformance.cases.server.trajectory import (
    FRACTION_TOL,
    LINE_TOL_MM,
    MOVING_DEG,
    OAT_TOL,
    val_angles,
    val_rotation,
    wrap180,
)
from manip.conformance.diff.pairing import SideEvent
from manip.conformance.diff.streams import Stream
from manip.conformance.fuzz.judge import Sighting
from manip.conformance.fuzz.steps import FuzzInput, Pause, Reconnect, RequestStep, Step
from manip.conformance.judge.checks import completed_segment, parse_description
from manip.conformance.judge.packets import WirePacket
from manip.conformance.judge.violation import Violation
from manip.conformance.suite.world import CalibrationFailure, Obstacle, SilentWrist, SluggishJoint
from manip.spec import SPEC
from manip.spec.constants import RequestName, ServerOp

__all__ = ["ANGLE_TOLERANCE", "SCENARIOS", "scenario", "scenarios"]

ANGLE_TOLERANCE: Final = 0.05
"""Degrees within which a joint angle read back is the angle commanded (the arm settles exactly in the
reference model; a real servo within a few hundredths)."""
SETTLE: Final = 30.0
"""Seconds of pause after a motion: a full-range move at speed 1 ends well within it."""
NZI_JOINTS: Final = (2, 3)
"""The joints whose zero index the calibrate-nzi condition hides (its default)."""
POSE: Final = (10.0, -80.0, 100.0, 20.0, 30.0, -40.0)
"""A pose within the PUMA 600's limits whose six angles all differ (a reversed or shifted vector shows)."""

READY_POSE: Final = (0.0, -90.0, 90.0, 0.0, 0.0, 0.0)

Events = dict[int, list[SideEvent]]


def _op(name: RequestName) -> int:
    return SPEC.request(name).opcode


def _req(name: RequestName, data: bytes = b"", *, lazy: bool = False) -> RequestStep:
    return RequestStep(_op(name), data, lazy=lazy)


def _floats(values: Sequence[float]) -> bytes:
    return b"".join(pack_f(v) for v in values)


def _inputs(name: str, groups: Sequence[tuple[str, Sequence[Step]]]) -> tuple[FuzzInput, ...]:
    return tuple(
        FuzzInput(n, f"scenario.{name}", tuple(steps), note) for n, (note, steps) in enumerate(groups)
    )


# What the answers say ------------------------------------------------------------------------------


def _answers(events: Sequence[SideEvent], opcode: int) -> list[SideEvent]:
    return [e for e in events if e.kind == "packet" and e.request == opcode]


def _payload(event: SideEvent) -> bytes:
    return event.data[2:]


def _angles(event: SideEvent) -> list[float] | None:
    body = _payload(event)
    if event.opcode != ServerOp.RESPONSE or len(body) % 4 or not body:
        return None
    try:
        return [unpack_f(body[i : i + 4]) for i in range(0, len(body), 4)]
    except (CodecError, ValueError):
        return None


def _read_back(events: Events, number: int) -> tuple[SideEvent, list[float]] | None:
    answer = next(iter(_answers(events.get(number, []), _op("joint-angles"))), None)
    angles = _angles(answer) if answer is not None else None
    return (answer, angles) if answer is not None and angles is not None else None


def _description(events: Events, number: int) -> dict[str, object] | None:
    packets = _answers(events.get(number, []), _op("describe-self"))
    text = "".join(decode_lispm(_payload(p)) for p in packets if p.opcode == ServerOp.RESPONSE)
    entries, problems = parse_description(text) if packets else (None, [])
    return dict(entries) if entries is not None and not problems else None


def _sighting(number: int, clause: str, message: str, expected: str, event: SideEvent) -> Sighting:
    return Sighting(Violation(message, clause, None, expected, event.show(), event.data), number)


def _close(got: Sequence[float], want: Sequence[float]) -> bool:
    return len(got) == len(want) and all(
        math.isclose(g, w, abs_tol=ANGLE_TOLERANCE) for g, w in zip(got, want, strict=True)
    )


def _swapped_words(body: bytes) -> list[float]:
    """The floats of ``body`` read with the two words of each swapped (NaN where that is no F value)."""
    out: list[float] = []
    for at in range(0, len(body) - 3, 4):
        try:
            out.append(unpack_f(body[at + 2 : at + 4] + body[at : at + 2]))
        except (CodecError, ValueError):
            out.append(math.nan)
    return out


def _shown(angles: Sequence[float]) -> str:
    return "(" + " ".join(f"{a:g}" for a in angles) + ")"


# The checks ----------------------------------------------------------------------------------------


def _check_read_back(at: int, pose: Sequence[float]) -> Callable[[Events], list[Sighting]]:
    """Joint angles read at input ``at`` after the arm was set to ``pose`` and came to rest."""

    def check(events: Events) -> list[Sighting]:
        got = _read_back(events, at)
        if got is None or _close(got[1], pose):
            return []
        answer, angles = got
        expected = f"the angles set, {_shown(pose)}, one per joint from the base"
        if _close(_swapped_words(_payload(answer)), pose):
            message = f"joint angles read {_shown(angles)}: the angles set with their two words swapped"
            return [_sighting(at, "float.format", message, expected, answer)]
        message = f"joint angles read {_shown(angles)} after the arm was set to {_shown(pose)}"
        return [_sighting(at, "joint-angles.reply", message, expected, answer)]

    return check


def _check_ready(described: int, before: int, after: int) -> Callable[[Events], list[Sighting]]:
    """After move to ready, the arm is at the stated :ready-position (``describe.ready-position``); a
    wrist left where it stood before is ``ready.pose`` broken (the ready position moves every joint)."""

    def check(events: Events) -> list[Sighting]:
        entries, got, prior = (
            _description(events, described),
            _read_back(events, after),
            _read_back(events, before),
        )
        stated = entries.get("ready-position") if entries is not None else None
        if (
            got is None
            or not isinstance(stated, list)
            or not all(isinstance(x, (int, float)) for x in stated)
        ):
            return []
        want = [float(x) for x in stated]
        answer, angles = got
        if _close(angles, want):
            return []
        if prior is not None and _close(angles[3:], prior[1][3:]) and not _close(prior[1][3:], want[3:]):
            message = f"after move to ready the wrist joints stayed at {_shown(angles[3:])}"
            return [_sighting(after, "ready.pose", message, f"the ready position {_shown(want)}", answer)]
        message = f"after move to ready the arm is at {_shown(angles)}, not the stated ready position"
        return [_sighting(after, "describe.ready-position", message, _shown(want), answer)]

    return check


def _check_nzi(at: int) -> Callable[[Events], list[Sighting]]:
    """Calibration's F NZI names joints 2 and 3 (the condition's): the mask 6."""

    def check(events: Events) -> list[Sighting]:
        fatal = [e for e in events.get(at, []) if e.kind == "packet" and e.opcode == ServerOp.FATAL_ERROR]
        if not fatal:
            return []
        try:
            error = parse_error(fatal[0].data[2:], body="packet")
        except (CodecError, ValueError):
            return []
        want = sum(1 << (j - 1) for j in NZI_JOINTS)
        if error.code != "NZI" or error.args == (want,):
            return []
        message = (
            f"F NZI carries {list(error.args)}, not the mask of joints {NZI_JOINTS} whose index was hidden"
        )
        return [_sighting(at, "calibrate.nzi-mask", message, f"the mask {want}", fatal[0])]

    return check


def _check_collision(at: int, after: Sequence[int]) -> Callable[[Events], list[Sighting]]:
    """A move into the obstacle the condition placed (input ``at``, the segment after it queued too)
    ends with an asynchronous error; from then on motion is refused AWA until a reset, and the segment
    queued behind the aborted one never completes, not even after the reset (``motion.abort``; the
    inputs ``after``)."""

    def check(events: Events) -> list[Sighting]:
        seen = [(n, e) for n in (at, *after) for e in events.get(n, [])]
        first = next(iter(events.get(at, [])), None)
        if first is None:
            return []
        aborted = next((i for i, (_, e) in enumerate(seen) if _is(e, ServerOp.ASYNCHRONOUS_ERROR)), None)
        if aborted is None:
            message = "a move into the obstacle ended without an asynchronous error"
            return [_sighting(at, "motion.collision", message, "an asynchronous collision error", first)]
        queued = {
            int.from_bytes(e.data[2:4], "little")
            for e in _answers(events.get(at, []), _op("set-joint-angles"))
            if e.opcode == ServerOp.RESPONSE and len(e.data) >= 4
        }
        late = [(n, e) for n, e in seen[aborted:] if completed_segment(_wire(e)) in queued]
        if late:
            message = "a segment queued before the abort completed after it"
            return [_sighting(late[0][0], "motion.abort", message, "the queued segments dropped", late[0][1])]
        out: list[Sighting] = []
        for number in [n for n in after[:1] if n > seen[aborted][0]]:  # only once the abort was seen
            for answer in _answers(events.get(number, []), _op("set-joint-angles")):
                if answer.opcode == ServerOp.RESPONSE:
                    message = "a motion request after the abort was accepted before any reset"
                    out.append(_sighting(number, "motion.abort", message, "E AWA", answer))
            for answer in _answers(events.get(number, []), _op("here")):
                if answer.opcode != ServerOp.RESPONSE:
                    message = "here, which moves nothing, was refused while motion was aborted"
                    clause = "motion.abort-serves-others"
                    out.append(_sighting(number, clause, message, "the transform, as usual", answer))
        return out

    return check


def _is(event: SideEvent, opcode: int) -> bool:
    return event.kind == "packet" and event.opcode == opcode


def _check_description(at: int) -> Callable[[Events], list[Sighting]]:
    """What describe self states at input ``at``: :joint-limits one (lower upper) pair per degree of
    freedom, lower not above upper (``describe.joint-limits-count``)."""

    def check(events: Events) -> list[Sighting]:
        entries = _description(events, at)
        limits, dof = (entries or {}).get("joint-limits"), (entries or {}).get("degrees-of-freedom")
        if not isinstance(limits, list) or not isinstance(dof, int):
            return []
        pairs = [p for p in limits if isinstance(p, list) and len(p) == 2 and p[0] <= p[1]]
        if len(pairs) == len(limits) == dof:
            return []
        first = _answers(events.get(at, []), _op("describe-self"))[0]
        message = f":joint-limits holds {len(pairs)} well-formed pair(s) of {len(limits)} for {dof} joints"
        return [_sighting(at, "describe.joint-limits-count", message, f"{dof} (lower upper) pairs", first)]

    return check


def _stated_limits(events: Events, at: int) -> tuple[tuple[float, float], ...]:
    entries = _description(events, at) or {}
    stated = entries.get("joint-limits")
    pairs = stated if isinstance(stated, list) else []
    if len(pairs) == 6 and all(isinstance(p, list) and len(p) == 2 for p in pairs):
        return tuple((float(p[0]), float(p[1])) for p in pairs)
    return tuple(zip(PUMA600.limits.lower, PUMA600.limits.upper, strict=True))


def _check_jor(described: int, probes: dict[int, tuple[float, ...]]) -> Callable[[Events], list[Sighting]]:
    """Set joint angles beyond a limit (the stated ones, else the PUMA 600's) is refused E JOR, whose
    number is the mask of the joints beyond (erratum error-arg-values)."""

    def check(events: Events) -> list[Sighting]:
        limits = _stated_limits(events, described)
        out: list[Sighting] = []
        for number, angles in probes.items():
            mask = sum(
                1 << j
                for j, (a, (lo, hi)) in enumerate(zip(angles, limits, strict=True))
                if not lo <= a <= hi
            )
            answer = next(iter(_answers(events.get(number, []), _op("set-joint-angles"))), None)
            if mask and answer is not None and answer.opcode == ServerOp.RESPONSE:
                message = "set joint angles beyond a joint's limit was accepted"
                out.append(_sighting(number, "motion.checked-before-queue", message, "E JOR", answer))
            if not mask or answer is None or answer.opcode != ServerOp.NON_FATAL_ERROR:
                continue
            try:
                error = parse_error(answer.data[2:], body="packet")
            except (CodecError, ValueError):
                continue
            if error.code != "JOR":
                message = f"set joint angles beyond a joint's limit was refused {error.code}, not JOR"
                out.append(_sighting(number, "motion.checked-before-queue", message, "E JOR", answer))
            elif error.args and error.args != (mask,):
                message = f"E JOR carries {list(error.args)}, not the mask of the joints beyond their limits"
                out.append(_sighting(number, "error-string.arg-values", message, f"the mask {mask}", answer))
        return out

    return check


def _check_fifo(at: int) -> Callable[[Events], list[Sighting]]:
    """The segments queued at input ``at`` complete in the order they were queued: the segment-completed
    reports name the numbers their requests were answered with, in that order."""

    def check(events: Events) -> list[Sighting]:
        here = events.get(at, [])
        queued = [
            int.from_bytes(e.data[2:4], "little")
            for e in _answers(here, _op("set-joint-angles"))
            if e.opcode == ServerOp.RESPONSE and len(e.data) >= 4
        ]
        reports = [(e, completed_segment(_wire(e))) for e in here if e.kind == "packet"]
        done = [(e, n) for e, n in reports if n is not None]
        if not done or [n for _, n in done] == queued[: len(done)]:
            return []
        shown = [n for _, n in done]
        message = f"segments queued as {queued} were reported completed as {shown}"
        return [_sighting(at, "segment.fifo-completion", message, f"completions {queued}", done[0][0])]

    return check


def _wire(event: SideEvent) -> WirePacket:
    return WirePacket("s2c", event.opcode, 0, 0, event.data)


def _all(*checks: Callable[[Events], list[Sighting]]) -> Callable[[Events], list[Sighting]]:
    def check(events: Events) -> list[Sighting]:
        return [s for c in checks for s in c(events)]

    return check


# The scenarios -------------------------------------------------------------------------------------


def _probe_data(opcode: int) -> bytes:
    op = SPEC.requests.get(opcode)
    size = op.request.fixed_size if op is not None else None
    return bytes((size or 0) + 2)


def _describe_probe() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [("describe self", [_req("describe-self")])]
    groups += [
        (f"opcode 0{op:o} with a wrong length", [RequestStep(op, _probe_data(op))])
        for op in range(0o200, 0o300)
    ]
    return Stream(
        None, _inputs("describe-probe", groups), scenario="describe-probe", check=_check_description(0)
    )


def _limits() -> Stream:
    """Each joint just inside and just beyond the PUMA 600's upper limit (the outer side only, as the
    describe cases probe): inside is done on an arm of those limits, beyond is JOR, and either one
    judged against the limits describe self stated."""
    upper = PUMA600.limits.upper
    groups: list[tuple[str, Sequence[Step]]] = [
        ("describe self, enable power", [_req("describe-self"), _req("enable-power")])
    ]
    for joint in range(6):
        for past in (-1.0, 1.0):
            angles = list(READY_POSE)
            angles[joint] = upper[joint] + past
            where = "inside" if past < 0 else "beyond"
            groups.append(
                (
                    f"joint {joint + 1} one degree {where} its limit",
                    [_req("set-joint-angles", _floats(angles))],
                )
            )
    probes = {n: _floats_of(steps) for n, (_, steps) in enumerate(groups) if n and n % 2 == 0}
    check = _all(_check_description(0), _check_jor(0, probes))
    return Stream(None, _inputs("joint-limits", groups), scenario="joint-limits", check=check)


def _floats_of(steps: Sequence[Step]) -> tuple[float, ...]:
    step = steps[0]
    assert isinstance(step, RequestStep)
    return tuple(unpack_f(step.data[i : i + 4]) for i in range(0, len(step.data), 4))


def _read_back_scenario() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        (
            "enable power, set joint angles, rest",
            [_req("enable-power"), _req("set-joint-angles", _floats(POSE)), Pause(SETTLE)],
        ),
        ("joint angles", [_req("joint-angles")]),
    ]
    return Stream(None, _inputs("read-back", groups), scenario="read-back", check=_check_read_back(1, POSE))


def _ready() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        ("describe self", [_req("describe-self")]),
        (
            "enable power, set joint angles, rest",
            [_req("enable-power"), _req("set-joint-angles", _floats(POSE)), Pause(SETTLE)],
        ),
        ("joint angles", [_req("joint-angles")]),
        ("move to ready, rest", [_req("ready"), Pause(SETTLE)]),
        ("joint angles", [_req("joint-angles")]),
    ]
    check = _all(_check_description(0), _check_read_back(2, POSE), _check_ready(0, 2, 4))
    return Stream(None, _inputs("ready", groups), scenario="ready", check=check)


def _speeds() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        (f"set speed {v:g}", [_req("set-speed", pack_f(v))]) for v in (0.0, -0.5, 1.5, 100.0, 0.5)
    ]
    return Stream(None, _inputs("speed-range", groups), scenario="speed-range")


def _no_power() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        (
            "set joint angles without power (the preamble killed it)",
            [_req("set-joint-angles", _floats(POSE))],
        ),
        ("move to ready without power", [_req("ready")]),
        ("here", [_req("here")]),
    ]
    return Stream(None, _inputs("no-power", groups), scenario="no-power")


def _free_joint() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        ("enable power, free joint 3", [_req("enable-power"), _req("free-joint", struct.pack("<H", 3))]),
        ("joint angles (discarded)", [_req("joint-angles")]),
        ("here, kill power", [_req("here"), _req("kill-power")]),
    ]
    return Stream(None, _inputs("free-joint", groups), scenario="free-joint")


def _unrequested() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        (
            "enable power, ready, rest (no notifications asked for)",
            [_req("enable-power"), _req("ready"), Pause(SETTLE)],
        ),
        ("here", [_req("here")]),
    ]
    return Stream(None, _inputs("unrequested-async", groups), scenario="unrequested-async")


def _notified() -> Stream:
    moves = [(0.0, -90.0, 90.0, 0.0, 0.0, 0.0), POSE, (0.0, -60.0, 60.0, 0.0, 10.0, 0.0)]
    groups: list[tuple[str, Sequence[Step]]] = [
        (
            "enable power, notifications 3",
            [_req("enable-power"), _req("request-notifications", struct.pack("<H", 3))],
        ),
        (
            "three segments queued, rest",
            [
                *(_req("set-joint-angles", _floats(m)) for m in moves),
                Pause(SETTLE),
                Pause(SETTLE),
                Pause(SETTLE),
            ],
        ),
        ("here", [_req("here")]),
        (
            "describe self, twice pipelined, here",
            [_req("describe-self", lazy=True), _req("describe-self", lazy=True), _req("here")],
        ),
    ]
    return Stream(None, _inputs("notified-motion", groups), scenario="notified-motion", check=_check_fifo(1))


def _fatal() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        ("enable power", [_req("enable-power")]),
        ("calibrate (no zero index on joints 2 and 3)", [_req("calibrate")]),
        ("here (on the connection the fatal error left)", [_req("here")]),
    ]
    return Stream(
        None,
        _inputs("fatal-error", groups),
        scenario="fatal-error",
        conditions=(CalibrationFailure(NZI_JOINTS),),
        check=_check_nzi(1),
    )


WARNED_GOAL: Final = (0.0, -20.0, 90.0, 0.0, 0.0, 0.0)
"""The goal of the warning scenario's long move of joint 2 (the sluggish joint lags on its way)."""
WARNED_READS: Final = 2.0
"""Seconds between the warning scenario's two reads of the joints after the warning."""


def _stream_order(events: Events) -> list[tuple[int, SideEvent]]:
    return [(n, e) for n in sorted(events) for e in events[n]]


def _check_async_number(events: Events) -> list[Sighting]:
    """An asynchronous error carries the number of the last request processed: the one whose answer
    came last before it (``async-error.request-number``, erratum async-last-processed)."""
    last: int | None = None
    for number, event in _stream_order(events):
        if event.kind != "packet" or len(event.data) < 2:
            continue
        said = int.from_bytes(event.data[:2], "little")
        if event.request is not None:
            last = said
        elif event.opcode == ServerOp.ASYNCHRONOUS_ERROR and last is not None and said != last:
            message = (
                f"an asynchronous error carries request number {said}; the last request answered was {last}"
            )
            return [_sighting(number, "async-error.request-number", message, f"request number {last}", event)]
    return []


def _check_warning(moved: int, read: int, goal: Sequence[float]) -> Callable[[Events], list[Sighting]]:
    """A warning does not interrupt work: after an asynchronous warning during the move (input
    ``moved``), no asynchronous error follows, and the arm, read twice at input ``read``, is still on
    its way (or at the goal) (``async-warning.format``)."""

    def check(events: Events) -> list[Sighting]:
        order = _stream_order(events)
        warned = next((i for i, (_, e) in enumerate(order) if _is(e, ServerOp.ASYNCHRONOUS_WARNING)), None)
        if warned is None:
            return []
        for _, event in order[warned:]:
            if _is(event, ServerOp.ASYNCHRONOUS_ERROR):
                message = "an asynchronous error followed the warning: the warning interrupted the motion"
                return [_sighting(moved, "async-warning.format", message, "the motion going on", event)]
        reads = _floats_at(events, read, "joint-angles")
        if len(reads) != 2 or not _close(reads[0][1], reads[1][1]) or _close(reads[1][1], goal):
            return []
        message = f"after the warning the arm stood still at {_shown(reads[1][1])}, short of {_shown(goal)}"
        return [_sighting(moved, "async-warning.format", message, "the motion going on", reads[1][0])]

    return check


def _sluggish() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        (
            "enable power, notifications 3",
            [_req("enable-power"), _req("request-notifications", struct.pack("<H", 3))],
        ),
        (
            "a long move of joint 2, rest",
            [_req("set-joint-angles", _floats(WARNED_GOAL)), Pause(SETTLE)],
        ),
        (
            "joint angles twice, seconds apart, here",
            [_req("joint-angles"), Pause(WARNED_READS), _req("joint-angles"), _req("here")],
        ),
    ]
    return Stream(
        None,
        _inputs("warning", groups),
        scenario="warning",
        conditions=(SluggishJoint(),),
        check=_check_warning(1, 2, WARNED_GOAL),
    )


def _check_wrist(at: int) -> Callable[[Events], list[Sighting]]:
    """While the wrist is silent, read forces (input ``at``) is answered with a non-fatal error, never
    left unanswered nor answered with a fatal one (``wrist.no-answer``)."""

    def check(events: Events) -> list[Sighting]:
        answer = next(iter(_answers(events.get(at, []), _op("read-forces"))), None)
        if answer is not None and answer.opcode == ServerOp.NON_FATAL_ERROR:
            return []
        if answer is None:
            message = "read forces got no answer while the wrist was silent"
            seen = SideEvent("stream", text="no answer to read forces")
        else:
            message = f"read forces was answered 0{answer.opcode:o} while the wrist was silent"
            seen = answer
        return [_sighting(at, "wrist.no-answer", message, "a non-fatal error (202)", seen)]

    return check


def _wrist_silent() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        ("read forces (the wrist does not answer)", [_req("read-forces")]),
        ("here", [_req("here")]),
    ]
    return Stream(
        None,
        _inputs("wrist-silent", groups),
        scenario="wrist-silent",
        conditions=(SilentWrist(),),
        check=_check_wrist(0),
    )


def _collision() -> Stream:
    into = _floats((0.0, -20.0, 90.0, 0.0, 0.0, 0.0))
    back = _floats((0.0, -80.0, 90.0, 0.0, 0.0, 0.0))
    groups: list[tuple[str, Sequence[Step]]] = [
        (
            "enable power, notifications 3",
            [_req("enable-power"), _req("request-notifications", struct.pack("<H", 3))],
        ),
        (
            "move joint 2 into the obstacle at -60 degrees, a segment queued behind it, rest",
            [_req("set-joint-angles", into), _req("set-joint-angles", back), Pause(SETTLE)],
        ),
        ("a motion request before any reset (AWA), here", [_req("set-joint-angles", back), _req("here")]),
        ("enable power (the reset), rest, here", [_req("enable-power"), Pause(SETTLE), _req("here")]),
    ]
    check = _all(_check_collision(1, (2, 3)), _check_async_number)
    return Stream(
        None,
        _inputs("collision", groups),
        scenario="collision",
        conditions=(Obstacle(2, upper=-60.0),),
        check=check,
    )


TINY: Final = 1e-38
HUGE: Final = 1.0e38


def _extremes() -> Stream:
    """The float extremes case's requests: solve backwards and forwards at the ends of the F range."""
    asks = [
        _req("solve-backwards", _floats((0.0, 0.0, 0.0, TINY, TINY, TINY))),
        _req("solve-backwards", _floats((TINY,) * 6)),
        _req("solve-backwards", _floats((HUGE, -HUGE, 1e20, 3e37, -HUGE, TINY))),
    ]
    for position in ((HUGE, HUGE, HUGE), (-HUGE, 0.0, TINY), (TINY, TINY, TINY)):
        transform = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, *position)
        asks.append(_req("solve-forwards", _floats(transform) + _floats(READY_POSE)))
    groups: list[tuple[str, Sequence[Step]]] = [(f"request {i}", [a]) for i, a in enumerate(asks)]
    groups.append(("here, joint angles", [_req("here"), _req("joint-angles")]))
    return Stream(None, _inputs("float-extremes", groups), scenario="float-extremes", check=_check_floats)


def _check_floats(events: Events) -> list[Sighting]:
    """Every float of every reply is an F value: never the reserved operand (a NaN or an infinity,
    ``float.not-finite``), and below 2^-128 a clean zero (``float.dirty-zero``)."""
    out: list[Sighting] = []
    for number, seen in events.items():
        for event in seen:
            if not _is(event, ServerOp.RESPONSE) or event.request not in _FLOAT_REPLIES:
                continue
            body = _payload(event)
            for i in range(0, len(body) - 3, 4):
                w0, w1 = struct.unpack_from("<HH", body, i)
                if (w0 >> 7) & 0xFF or not (w0 or w1):
                    continue
                clause = "float.not-finite" if w0 & 0x8000 else "float.dirty-zero"
                message = f"float words {w0:04x} {w1:04x} at byte {i} of the reply"
                out.append(_sighting(number, clause, message, "an F value, zero all bits clear", event))
                break
    return out


_FLOAT_REPLIES: Final = frozenset(
    SPEC.request(n).opcode for n in ("here", "joint-angles", "solve-forwards", "solve-backwards")
)


# What a connection leaves behind, and the arm's pose after a request --------------------------------

REST: Final = 5.0
"""Seconds of pause after a move of these scenarios (a few tens of degrees: well within it)."""
SEED_ANGLES: Final = CONFIGURATION_SEED
"""Joint angles whose transform has a lefty and a righty solution in range (the configuration cases')."""
SLOW: Final = 0.25
"""The slow speed factor: the one a first connection leaves behind, and the one a swing is timed at."""
SWING_DEG: Final = 30.0
"""How far joint 1 swings in a timed move (from the ready position)."""
MIDWAY: Final = 0.4
"""Seconds after a timed move is answered that the scenario reads the joints: mid-move at factor 1."""
STILL: Final = 1.0
"""Seconds between two reads that show the arm at rest (the same both times) before it is judged."""
INCREMENT: Final = ((0.0, 0.0, -30.0), (25.0, 0.0, 0.0))
"""The deltas (mm) of the two incremental moves queued back to back."""
OAT_TURN: Final = (12.0, 0.0, 0.0)
"""dO dA dT of the incremental turn (dO alone: added to T instead, it shows)."""


def _seed_transform() -> tuple[float, ...]:
    return forward(SEED_ANGLES, PUMA600.geometry).to_floats()


def _solve_seed() -> RequestStep:
    return _req("solve-forwards", _floats(_seed_transform()) + _floats(SEED_ANGLES))


def _word(value: int) -> bytes:
    return struct.pack("<H", value)


def _responses(events: Events, number: int, name: RequestName) -> list[SideEvent]:
    return [e for e in _answers(events.get(number, []), _op(name)) if e.opcode == ServerOp.RESPONSE]


def _solution(events: Events, number: int) -> tuple[SideEvent, list[float]] | None:
    """The first solve forwards answered with six angles at input ``number``."""
    for answer in _responses(events, number, "solve-forwards"):
        angles = _angles(answer)
        if angles is not None and len(angles) == 6:
            return answer, angles
    return None


def _segment(events: Events, number: int) -> tuple[SideEvent, int] | None:
    """The first segment number a set joint angles was answered with at input ``number``."""
    for answer in _responses(events, number, "set-joint-angles"):
        if len(answer.data) >= 4:
            return answer, int.from_bytes(answer.data[2:4], "little")
    return None


def _floats_at(events: Events, number: int, name: RequestName) -> list[tuple[SideEvent, list[float]]]:
    """Every answer of ``name`` at input ``number`` read as floats, in order."""
    out = []
    for answer in _responses(events, number, name):
        values = _angles(answer)
        if values is not None:
            out.append((answer, values))
    return out


def _check_configuration(lefty: int, righty: int) -> Callable[[Events], list[Sighting]]:
    """Solve forwards of the seed's transform after set configuration 1 (input ``lefty``) and 0
    (``righty``): two different solutions (``set-configuration.effect``), the first lefty and the second
    righty by the arm's geometry (raising joint 2 alone lowers the wrist in a lefty one,
    ``set-configuration.lefty-side``).  Judged where the first answer is (what follows it differs for it)."""

    def check(events: Events) -> list[Sighting]:
        got_l, got_r = _solution(events, lefty), _solution(events, righty)
        if got_l is None or got_r is None:
            return []
        (answer, left), (_, right) = got_l, got_r
        if _close(left, right):
            message = f"set configuration 1 and 0 gave one solution, {_shown(left)}"
            expected = "a lefty and a righty solution (the transform has both in range)"
            return [_sighting(lefty, "set-configuration.effect", message, expected, answer)]
        sides = [configuration(q, PUMA600.geometry)[0] for q in (left, right)]
        if sides == [True, False]:
            return []
        shown = ", ".join("lefty" if s else "righty" for s in sides)
        message = f"the solutions after set configuration 1 and 0 are {shown}"
        return [_sighting(lefty, "set-configuration.lefty-side", message, "lefty, then righty", answer)]

    return check


def _configuration() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        ("set configuration 1, solve forwards", [_req("set-configuration", _word(1)), _solve_seed()]),
        ("set configuration 0, solve forwards", [_req("set-configuration", _word(0)), _solve_seed()]),
    ]
    return Stream(
        None, _inputs("configuration", groups), scenario="configuration", check=_check_configuration(0, 1)
    )


def _check_increments(start: int, end: int, turned: int) -> Callable[[Events], list[Sighting]]:
    """Here at input ``start``, after two incremental moves queued back to back (``end``) and after an
    incremental turn by :data:`OAT_TURN` (``turned``), each judged once the arm is at rest: the hand
    moved by both deltas, orientation kept, then turned by dO dA dT of VAL's angles, position kept
    (``incremental.relative``)."""

    def check(events: Events) -> list[Sighting]:
        first, moved, last = (_read_here(events, n) for n in (start, end, turned))
        if not (_all_done(events, end, 2) and _at_rest(events, end)):
            return []  # refused (out of reach in the side's unit, say), or still moving: nothing to judge
        if not (_all_done(events, turned, 1) and _at_rest(events, turned)):
            last = None
        out: list[Sighting] = []
        if first is not None and moved is not None:
            want = [p + sum(d[i] for d in INCREMENT) for i, p in enumerate(first[1][9:])]
            off = math.dist(moved[1][9:], want)
            turn = max(abs(x - y) for x, y in zip(moved[1][:9], first[1][:9], strict=True))
            if off > HAND_TOL_MM or turn > OAT_TOL:
                message = (
                    f"after both incremental moves the hand is {off:.3g} mm from the start plus both deltas"
                )
                out.append(_sighting(end, "incremental.relative", message, _shown(want), moved[0]))
        if moved is not None and last is not None:
            o, a, t = val_angles(moved[1])
            want_r = val_rotation(o + OAT_TURN[0], a + OAT_TURN[1], t + OAT_TURN[2])
            got = tuple(tuple(last[1][3 * j + i] for j in range(3)) for i in range(3))
            turn = max(abs(want_r[i][j] - got[i][j]) for i in range(3) for j in range(3))
            if turn > OAT_TOL or math.dist(last[1][9:], moved[1][9:]) > HAND_TOL_MM:
                message = f"after an incremental turn by dO dA dT {OAT_TURN} the rotation is {turn:.3g} off"
                expected = f"O A T {_shown((o, a, t))} plus {_shown(OAT_TURN)}, position kept"
                out.append(_sighting(turned, "incremental.relative", message, expected, last[0]))
        return out

    return check


def _all_done(events: Events, number: int, count: int) -> bool:
    """Whether the ``count`` incremental moves of input ``number`` were each answered with a segment."""
    names: tuple[RequestName, ...] = ("incremental-move", "incremental-straight-move")
    answers = [e for n in names for e in _answers(events.get(number, []), _op(n))]
    return len(answers) == count and all(e.opcode == ServerOp.RESPONSE for e in answers)


def _at_rest(events: Events, number: int) -> bool:
    """Whether the last two Here answers of input ``number``, :data:`STILL` seconds apart, agree."""
    got = _floats_at(events, number, "here")
    return len(got) >= 2 and _close(got[-2][1], got[-1][1])


def _read_here(events: Events, number: int) -> tuple[SideEvent, list[float]] | None:
    got = _floats_at(events, number, "here")
    return got[-1] if got and len(got[-1][1]) == 12 else None


def _increments() -> Stream:
    def delta(values: Sequence[float]) -> bytes:
        return _floats(values)

    groups: list[tuple[str, Sequence[Step]]] = [
        (
            "enable power, set joint angles, rest, here",
            [_req("enable-power"), _req("set-joint-angles", _floats(SEED_ANGLES)), Pause(REST), _req("here")],
        ),
        (
            "two incremental moves queued back to back, rest, here twice",
            [
                _req("incremental-move", delta((*INCREMENT[0], 0.0, 0.0, 0.0))),
                _req("incremental-straight-move", delta((*INCREMENT[1], 0.0, 0.0, 0.0))),
                Pause(REST),
                _req("here"),
                Pause(STILL),
                _req("here"),
            ],
        ),
        (
            "an incremental turn, rest, here twice",
            [
                _req("incremental-move", delta((0.0, 0.0, 0.0, *OAT_TURN))),
                Pause(REST),
                _req("here"),
                Pause(STILL),
                _req("here"),
            ],
        ),
    ]
    return Stream(
        None, _inputs("increments", groups), scenario="increments", check=_check_increments(0, 1, 2)
    )


def _check_joint_order(before: int, after: int) -> Callable[[Events], list[Sighting]]:
    """Element 1 of a joint vector is the waist: set joint angles with element 1 alone changed by
    :data:`SWING_DEG` turns the hand about the base's z axis by as much, at the same height and distance
    from the axis (``joint-angles.reply``)."""

    def check(events: Events) -> list[Sighting]:
        first, last = _read_here(events, before), _read_here(events, after)
        if first is None or last is None:
            return []
        p0, p1 = first[1][9:], last[1][9:]
        turned = wrap180(math.degrees(math.atan2(p1[1], p1[0]) - math.atan2(p0[1], p0[0])))
        if (
            abs(p1[2] - p0[2]) <= HAND_TOL_MM
            and abs(math.hypot(p1[0], p1[1]) - math.hypot(p0[0], p0[1])) <= HAND_TOL_MM
            and abs(turned - SWING_DEG) <= TURN_TOL_DEG
        ):
            return []
        message = f"element 1 turned by {SWING_DEG:g} deg moved the hand {_shown(p0)} -> {_shown(p1)}"
        expected = f"the hand turned {SWING_DEG:g} deg about the base's z axis (element 1 the waist)"
        # Judged where the first Here is: the hand at the angles set already differs for it.
        return [_sighting(before, "joint-angles.reply", message, expected, first[0])]

    return check


def _joint_order() -> Stream:
    swung = (READY_POSE[0] + SWING_DEG, *READY_POSE[1:])
    groups: list[tuple[str, Sequence[Step]]] = [
        (
            "enable power, set joint angles to ready, rest, here",
            [_req("enable-power"), _req("set-joint-angles", _floats(READY_POSE)), Pause(REST), _req("here")],
        ),
        (
            "element 1 alone turned, rest, here",
            [_req("set-joint-angles", _floats(swung)), Pause(REST), _req("here")],
        ),
    ]
    return Stream(
        None, _inputs("joint-order", groups), scenario="joint-order", check=_check_joint_order(0, 1)
    )


def _timed_move(goal: Sequence[float]) -> list[Step]:
    return [_req("set-joint-angles", _floats(goal)), Pause(MIDWAY), _req("joint-angles"), Pause(REST)]


def _progress(start: float, goal: float, at: float) -> float:
    return (at - start) / (goal - start)


def _check_fresh(
    first: int, queued: int, solved: int, moved: int, timed: int
) -> Callable[[Events], list[Sighting]]:
    """The second connection (from input ``solved``) finds none of what the first set
    (``connect.per-connection-state``): solve forwards gives the solution the first gave before set
    configuration (input ``first``), its first move is never refused AWA (input ``moved``) and has the
    segment number the first connection's first move had (input ``queued``), no asynchronous response
    comes unasked, and a move gets as far midway as one at an explicit factor 1 (input ``timed``)."""

    def check(events: Events) -> list[Sighting]:
        out: list[Sighting] = []
        fresh, again = _solution(events, first), _solution(events, solved)
        if fresh is not None and again is not None and not _close(fresh[1], again[1]):
            message = (
                f"solve forwards gave {_shown(again[1])} anew, {_shown(fresh[1])} on the first connection"
            )
            out.append(_sighting(solved, _FRESH, message, "the fresh connection's solution", again[0]))
        out += _first_move(events, queued, moved, timed)
        out += _unasked(events, moved, timed)
        out += _fresh_speed(events, timed)
        return out

    return check


_FRESH: Final = "connect.per-connection-state"


def _first_move(events: Events, queued: int, moved: int, timed: int) -> list[Sighting]:
    out: list[Sighting] = []
    for answer in _answers(events.get(moved, []), _op("set-joint-angles"))[:1]:
        with contextlib.suppress(CodecError, ValueError):
            if (
                answer.opcode == ServerOp.NON_FATAL_ERROR
                and parse_error(answer.data, body="packet").code == "AWA"
            ):
                message = "the new connection's first move was refused AWA: the last connection's abort"
                out.append(_sighting(moved, _FRESH, message, "done, or NAP without power", answer))
    at = moved if _segment(events, moved) is not None else timed  # NAP: the first move is later
    old, new = _segment(events, queued), _segment(events, at)
    if old is not None and new is not None and new[1] != old[1]:
        message = f"the new connection's first segment is {new[1]}, the first connection's was {old[1]}"
        out.append(_sighting(at, _FRESH, message, "the segment counter afresh", new[0]))
    return out


def _unasked(events: Events, moved: int, timed: int) -> list[Sighting]:
    for number in range(moved, timed + 1):
        for event in events.get(number, []):
            if _is(event, ServerOp.ASYNCHRONOUS_RESPONSE):
                message = "an asynchronous response on a connection that asked for none"
                expected = "none: the last connection's notifications are not in force"
                return [_sighting(number, _FRESH, message, expected, event)]
    return []


def _fresh_speed(events: Events, timed: int) -> list[Sighting]:
    """A swing at the fresh connection's speed gets as far midway as the one back at factor 1."""
    got = _midway(events, timed)
    if got is None or got[0] * SPEED_MATCH >= got[1]:
        return []
    default, explicit, event = got
    message = f"midway a move got {default:.0%} of its way at the fresh speed, {explicit:.0%} at factor 1"
    return [_sighting(timed, _FRESH, message, "the fresh connection moving at factor 1", event)]


def _fresh_connection() -> Stream:
    swung = (READY_POSE[0] + SWING_DEG, *READY_POSE[1:])
    groups: list[tuple[str, Sequence[Step]]] = [
        ("solve forwards (no configuration set)", [_solve_seed()]),
        (
            "enable power, a move to ready, set configuration 0, a slow speed, notifications 3",
            [
                _req("enable-power"),
                _req("set-joint-angles", _floats(READY_POSE)),
                _req("set-configuration", _word(0)),
                _req("set-speed", pack_f(SLOW)),
                _req("request-notifications", _word(3)),
            ],
        ),
        (
            "a move cut short by kill power (an abort stands), a new connection",
            [_req("set-joint-angles", _floats(swung)), _req("kill-power"), Pause(1.0), Reconnect()],
        ),
        ("solve forwards", [_solve_seed()]),
        ("set joint angles to ready", [_req("set-joint-angles", _floats(READY_POSE))]),
        (
            "to ready, a timed swing, one back at factor 1",
            _timed_pair([]),
        ),
    ]
    check = _check_fresh(0, 1, 3, 4, 5)
    return Stream(None, _inputs("fresh-connection", groups), scenario="fresh-connection", check=check)


def _check_still(at: int) -> Callable[[Events], list[Sighting]]:
    """Joint angles read twice, seconds apart, on the connection after one closed under a move: the
    same (``connect.close-stops-arm``)."""

    def check(events: Events) -> list[Sighting]:
        reads = _floats_at(events, at, "joint-angles")
        if len(reads) != 2 or _close(reads[0][1], reads[1][1]):
            return []
        message = (
            f"the arm moved from {_shown(reads[0][1])} to {_shown(reads[1][1])} after the connection closed"
        )
        return [_sighting(at, "connect.close-stops-arm", message, "the arm standing still", reads[1][0])]

    return check


def _close_moving() -> Stream:
    far = (READY_POSE[0] + 90.0, *READY_POSE[1:])
    groups: list[tuple[str, Sequence[Step]]] = [
        (
            "enable power, to ready, rest, a long move, a new connection at once",
            [
                _req("enable-power"),
                _req("set-joint-angles", _floats(READY_POSE)),
                Pause(REST),
                _req("set-joint-angles", _floats(far)),
                Reconnect(),
            ],
        ),
        ("joint angles twice, seconds apart", [_req("joint-angles"), Pause(2.0), _req("joint-angles")]),
    ]
    return Stream(None, _inputs("close-moving", groups), scenario="close-moving", check=_check_still(1))


def _midway(events: Events, timed: int) -> tuple[float, float, SideEvent] | None:
    """How far joint 1 got midway through a swing from the ready position (read before it) and midway
    through the one back (read at its goal): the joint angles read four times at input ``timed``."""
    reads = _floats_at(events, timed, "joint-angles")
    if len(reads) != 4:
        return None
    start, first, goal, second = (r[1][0] for r in reads)
    there = READY_POSE[0] + SWING_DEG
    if not (_close([start], [READY_POSE[0]]) and _close([goal], [there])):
        return None
    return _progress(start, there, first), _progress(there, start, second), reads[1][0]


def _check_speed_scales(timed: int) -> Callable[[Events], list[Sighting]]:
    """A swing at factor :data:`SLOW` gets at most 1 / :data:`SPEED_MATCH` as far midway as the one back at
    factor 1 (``motion.speed-scales``)."""

    def check(events: Events) -> list[Sighting]:
        got = _midway(events, timed)
        if got is None or got[0] * SPEED_MATCH <= got[1]:
            return []
        slow, full, event = got
        message = f"midway a move got {slow:.0%} of its way at factor {SLOW:g}, {full:.0%} at factor 1"
        return [
            _sighting(timed, "motion.speed-scales", message, f"the move {1 / SLOW:g} times slower", event)
        ]

    return check


def _timed_pair(first: Sequence[Step]) -> list[Step]:
    """To ready, the joints read, ``first`` (a speed), a timed swing, the joints read, factor 1, a timed
    swing back."""
    swung = (READY_POSE[0] + SWING_DEG, *READY_POSE[1:])
    return [
        _req("enable-power"),
        _req("set-joint-angles", _floats(READY_POSE)),
        Pause(REST),
        _req("joint-angles"),
        *first,
        *_timed_move(swung),
        _req("joint-angles"),
        _req("set-speed", pack_f(1.0)),
        *_timed_move(READY_POSE),
    ]


def _speed_scales() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        (
            f"a timed swing at factor {SLOW:g}, one back at factor 1",
            _timed_pair([_req("set-speed", pack_f(SLOW))]),
        )
    ]
    return Stream(
        None, _inputs("speed-scales", groups), scenario="speed-scales", check=_check_speed_scales(0)
    )


def _check_not_split(at: int) -> Callable[[Events], list[Sighting]]:
    """No other packet comes between the first packet of describe self's reply at input ``at`` and its
    terminator (``multi.not-split``)."""

    def check(events: Events) -> list[Sighting]:
        seen = events.get(at, [])
        mine = [i for i, e in enumerate(seen) if e.kind == "packet" and e.request == _op("describe-self")]
        if not mine:
            return []
        inside = [e for e in seen[mine[0] : mine[-1]] if e.kind == "packet" and e.request is None]
        if not inside:
            return []
        message = f"0{inside[0].opcode:o} came inside describe self's reply"
        return [
            _sighting(at, "multi.not-split", message, "the reply whole, then the other packets", inside[0])
        ]

    return check


def _split() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        (
            "enable power, notifications 3, a move, rest",
            [
                _req("enable-power"),
                _req("request-notifications", _word(3)),
                _req("set-joint-angles", _floats(POSE)),
                Pause(REST),
            ],
        ),
        ("describe self", [_req("describe-self")]),
    ]
    return Stream(None, _inputs("not-split", groups), scenario="not-split", check=_check_not_split(1))


LINE_SHIFT: Final = (80.0, 40.0, -60.0)
"""How far (mm) the paths scenario's straight-line move takes the hand from the seed's pose."""
JOINT_SHIFT: Final = (30.0, 20.0, -25.0, 15.0, 20.0, -30.0)
"""How far (deg) each joint goes in the paths scenario's joint-interpolated move to a transform."""


def _shifted(angles: Sequence[float], shift: Sequence[float]) -> bytes:
    """The transform of ``angles`` with its position moved by ``shift`` (mm)."""
    floats = list(forward(angles, PUMA600.geometry).to_floats())
    floats[9:] = [p + d for p, d in zip(floats[9:], shift, strict=True)]
    return _floats(floats)


def _off_line(p: Sequence[float], a: Sequence[float], b: Sequence[float]) -> tuple[float, float]:
    """The distance of ``p`` from the line through ``a`` and ``b``, and how far along it p lies (0 to 1)."""
    ab = [y - x for x, y in zip(a, b, strict=True)]
    length = math.hypot(*ab)
    if length == 0:
        return 0.0, 0.0
    along = sum((q - x) * d for q, x, d in zip(p, a, ab, strict=True)) / length**2
    nearest = [x + along * d for x, d in zip(a, ab, strict=True)]
    return math.dist(p, nearest), along


def _check_paths(line: int, joint: int) -> Callable[[Events], list[Sighting]]:
    """Midway through a straight-line move (input ``line``: Here before, midway, at the end) the hand is
    on the line from where it started to where it ended (``straight-move.line``); midway through a move
    (input ``joint``: joint angles before, midway, at the end) the joints that move are at one fraction
    of their ways (``joint-move.interpolated``)."""

    def check(events: Events) -> list[Sighting]:
        out: list[Sighting] = []
        heres = _floats_at(events, line, "here")
        if len(heres) == 3 and all(len(h[1]) == 12 for h in heres):
            start, mid, end = (h[1][9:] for h in heres)
            off, along = _off_line(mid, start, end)
            if 0.0 < along < 1.0 and off > LINE_TOL_MM:
                message = (
                    f"midway the hand is {off:.3g} mm off the line from {_shown(start)} to {_shown(end)}"
                )
                out.append(
                    _sighting(line, "straight-move.line", message, "the hand on the line", heres[1][0])
                )
        reads = _floats_at(events, joint, "joint-angles")
        if len(reads) == 3:
            first, mid, last = (r[1] for r in reads)
            moving = [i for i, (a, b) in enumerate(zip(first, last, strict=True)) if abs(b - a) >= MOVING_DEG]
            fractions = [(mid[i] - first[i]) / (last[i] - first[i]) for i in moving]
            spread = max(fractions) - min(fractions) if fractions else 0.0
            if spread > FRACTION_TOL:
                message = f"midway the moving joints were {spread:.3f} apart in the fractions of their ways"
                expected = "every moving joint at one fraction of its way"
                out.append(_sighting(joint, "joint-move.interpolated", message, expected, reads[1][0]))
        return out

    return check


def _paths() -> Stream:
    start = _floats(SEED_ANGLES)
    goal = tuple(a + d for a, d in zip(SEED_ANGLES, JOINT_SHIFT, strict=True))
    groups: list[tuple[str, Sequence[Step]]] = [
        (
            "enable power, to the seed's angles, rest",
            [_req("enable-power"), _req("set-joint-angles", start), Pause(REST)],
        ),
        (
            "here, a straight-line move, here midway and at the end",
            [
                _req("here"),
                _req("straight-move", _shifted(SEED_ANGLES, LINE_SHIFT)),
                Pause(MIDWAY),
                _req("here"),
                Pause(REST),
                _req("here"),
            ],
        ),
        ("back to the seed's angles, rest", [_req("set-joint-angles", start), Pause(REST)]),
        (
            "joint angles, a move to a transform, joint angles midway and at the end",
            [
                _req("joint-angles"),
                _req("move", _shifted(goal, (0.0, 0.0, 0.0))),
                Pause(MIDWAY),
                _req("joint-angles"),
                Pause(REST),
                _req("joint-angles"),
            ],
        ),
    ]
    return Stream(None, _inputs("paths", groups), scenario="paths", check=_check_paths(1, 3))


SCENARIOS: Final[dict[str, Callable[[], Stream]]] = {
    "describe-probe": _describe_probe,
    "joint-limits": _limits,
    "read-back": _read_back_scenario,
    "ready": _ready,
    "speed-range": _speeds,
    "no-power": _no_power,
    "free-joint": _free_joint,
    "unrequested-async": _unrequested,
    "notified-motion": _notified,
    "fatal-error": _fatal,
    "warning": _sluggish,
    "wrist-silent": _wrist_silent,
    "collision": _collision,
    "float-extremes": _extremes,
    "configuration": _configuration,
    "increments": _increments,
    "joint-order": _joint_order,
    "fresh-connection": _fresh_connection,
    "close-moving": _close_moving,
    "speed-scales": _speed_scales,
    "not-split": _split,
    "paths": _paths,
}
"""Every scenario by name, in the order a diff sends them."""


def scenario(name: str) -> Stream:
    """The scenario ``name`` (KeyError for an unknown one)."""
    return SCENARIOS[name]()


def scenarios(*, world: bool = True) -> list[Stream]:
    """Every scenario; without ``world``, only those that need no condition of the arm's world."""
    out = [make() for make in SCENARIOS.values()]
    return [s for s in out if world or not s.conditions]
