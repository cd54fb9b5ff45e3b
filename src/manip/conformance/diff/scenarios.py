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
difference on that input is a violation (class a) naming the clause.

Some scenarios need a condition of the arm's world (``conditions``: the world contract's
:class:`~manip.conformance.suite.world.Condition`, as the directed cases arrange them): an embedded
side's world arranges them at once; an addressed side's through its ``--world-a/-b`` (contract 2).  A
side whose world cannot arrange one, or that has none, is not sent the scenario (the report says
so).  Sans-I/O.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Sequence
from typing import Final

from manip.arm.kinematics import PUMA600
from manip.codecs.error_string import parse_error
from manip.codecs.errors import CodecError
from manip.codecs.lispm_text import decode_lispm
from manip.codecs.pdp11float import pack_f, unpack_f
from manip.conformance.diff.pairing import SideEvent
from manip.conformance.diff.streams import Stream
from manip.conformance.fuzz.judge import Sighting
from manip.conformance.fuzz.steps import FuzzInput, Pause, RequestStep, Step
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
        for number in after[:1]:
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


def _sluggish() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        (
            "enable power, notifications 3",
            [_req("enable-power"), _req("request-notifications", struct.pack("<H", 3))],
        ),
        (
            "a long move of joint 2, rest",
            [_req("set-joint-angles", _floats((0.0, -20.0, 90.0, 0.0, 0.0, 0.0))), Pause(SETTLE)],
        ),
        ("joint angles, here", [_req("joint-angles"), _req("here")]),
    ]
    return Stream(None, _inputs("warning", groups), scenario="warning", conditions=(SluggishJoint(),))


def _wrist_silent() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        ("read forces (the wrist does not answer)", [_req("read-forces")]),
        ("here", [_req("here")]),
    ]
    return Stream(None, _inputs("wrist-silent", groups), scenario="wrist-silent", conditions=(SilentWrist(),))


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
    check = _check_collision(1, (2, 3))
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
}
"""Every scenario by name, in the order a diff sends them."""


def scenario(name: str) -> Stream:
    """The scenario ``name`` (KeyError for an unknown one)."""
    return SCENARIOS[name]()


def scenarios(*, world: bool = True) -> list[Stream]:
    """Every scenario; without ``world``, only those that need no condition of the arm's world."""
    out = [make() for make in SCENARIOS.values()]
    return [s for s in out if world or not s.conditions]
