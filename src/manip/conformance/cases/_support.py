"""Helpers of the server cases (no cases are declared here); the one place they live.

Valid request values are built from the spec's field types and from what the target itself reports
(its current transform and joint angles), so a well-formed request is valid for any arm: a move to
where the arm stands, a zero increment, the ready position.  For the property and stateful cases: what
the target says about its arm (:func:`describe_target`), one request/answer exchange as the model sees
it (:func:`reply_view`), and failures that carry their evidence (:class:`Evidence`).

A case reports only the clauses it declares (``manip.conformance.suite.invariants``), so the helpers
that a case uses to *prepare* its check (read the angles, switch power on) judge nothing themselves:
:func:`require_response` passes a malformed answer to the transcript invariant and, when the target
refuses what the case needs, ends the case not judged (it applies, but cannot be judged without what was
refused; the case of that request judges the refusal): a wrong answer is never a skip.  The helpers that
check take the clause from their caller.

The guide's own route (a server written from the 1985 guide alone has none of manip's Puma extension
opcodes): :func:`ask_notifications` says whether the target serves request notifications (0257), and when
it does not, a case learns what the notifications would have told it by polling Joint angles (0202) in the
run's clock: :func:`poll_joints`, :func:`arrival` (the end of a motion) and :func:`timed_move` (a move's
duration, either way).  :func:`extension_name` names an extension opcode the way every message does.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, replace
from typing import Any, Final, NamedTuple, NoReturn

from manip.arm.kinematics import PUMA600, JointLimits, Joints
from manip.arm.units import MM_PER_UNIT
from manip.codecs.errors import CodecError
from manip.codecs.lisp import LispValue
from manip.codecs.messages import ErrorReply, decode_error, decode_reply
from manip.conformance.judge.checks import (
    ANSWER_OPCODES,
    WirePacket,
    check_error_packet,
    check_reply,
    completed_segment,
    description_operations,
    multi_text,
    parse_description,
    word,
)
from manip.conformance.judge.model import AnswerSummary
from manip.conformance.judge.violation import CarriesViolation, Violation, showing
from manip.conformance.suite.context import DONE_SIZE, Answer, CaseContext, Probe
from manip.conformance.suite.invariants import TRANSCRIPT
from manip.spec import SPEC, RequestName, RequestOpcode
from manip.spec.constants import ERROR_STRING_OPS, AsyncCondition, ServerOp
from manip.spec.notation import octal

UNASSIGNED_OPCODES: Final[tuple[int, ...]] = tuple(
    code for code in range(0o200, 0o400) if code not in SPEC.requests
)
"""Data opcodes the spec gives no request (0222-0237, 0262-0377)."""

NOT_SERVED: Final = frozenset({"UOP", "UIM"})
"""The error codes of a request the target does not serve: an unknown opcode (request.unknown-opcode)
and an operation this arm does not implement (a wrist opcode without a wrist computer)."""
SMALL_DEFAULT: Final = 1
"""A valid ``small`` value for every opcode that has one (joint 1; configuration lefty)."""
FLOAT_DEFAULT: Final = 0.5
"""A valid single float for every opcode that has one (speed factor, weight, guard tolerance)."""


def floats(answer: Answer) -> tuple[float, ...]:
    """The floats of a data reply (transform or joints), decoded by the request's layout."""
    op = SPEC.requests[answer.request.opcode]
    reply = decode_reply(answer.data, op)
    out: list[float] = []
    for value in reply.values.values():
        if isinstance(value, tuple):
            out += [float(v) for v in value]
        elif isinstance(value, float):
            out.append(value)
    return tuple(out)


def require_response(ctx: CaseContext, answer: Answer, what: str) -> None:
    """The case needs ``answer`` to be a normal response: a malformed answer is a violation of the
    transcript invariant (reported here, and the case stops: what follows reads the answer), and a
    refusal ends the case not judged (:func:`refused`)."""
    ctx.check(check_reply(answer.request, answer.packets), stop=True)
    if not answer.is_response:
        refused(ctx, answer, f"the case needs {what}")


def refused(ctx: CaseContext, answer: Answer, needed: str) -> NoReturn:
    """End a case whose request was refused, not judged: the case applies, but cannot be judged without
    what was refused.  When the target does not serve the opcode (C UOP or C UIM: a capability it lacks,
    such as a Puma extension), a target that serves it judges the case's clauses; otherwise the opcode's
    own case judges the refusal.  A wrong answer is never a skip."""
    error = error_of(answer)
    op = SPEC.requests.get(answer.request.opcode)
    name = op.name if op is not None else f"opcode {octal(answer.request.opcode)}"
    said = repr(error.error.render()) if error is not None else str(answer)
    if error is not None and error.error.code in NOT_SERVED:
        ctx.not_judged(
            f"{needed}, and the target does not serve {name}: {said}; a target that serves it judges the "
            "case's clauses"
        )
    ctx.not_judged(f"{needed}, and the target refused {name}: {said} (server.reply.{name} judges the answer)")


async def read_floats(ctx: CaseContext, probe: Probe, op: RequestName) -> tuple[float, ...]:
    """Here or joint angles, as floats (the case is not judged when the target refuses them)."""
    answer = await probe.call(op)
    require_response(ctx, answer, f"a normal reply to {op}")
    try:
        return floats(answer)
    except CodecError as exc:  # check_reply decodes alike, so it has reported this already
        raise AssertionError(f"{op} reply does not decode, yet the reply checker passed it: {exc}") from exc


async def valid_values(ctx: CaseContext, probe: Probe, op: RequestOpcode) -> dict[str, Any]:
    """Values for a well-formed request of ``op`` that any conforming arm can carry out."""
    values: dict[str, Any] = {}
    for f in op.request.fields:
        ft = f.type
        if ft.name == "transform":
            values[f.name] = list(await read_floats(ctx, probe, "here"))
        elif ft.name == "joints":
            values[f.name] = list(await read_floats(ctx, probe, "joint-angles"))
        elif ft.element == "float":
            values[f.name] = FLOAT_DEFAULT if ft.count == 1 else [0.0] * (ft.count or 0)
        elif ft.element == "small":
            values[f.name] = SMALL_DEFAULT
        elif ft.element in ("word", "int16"):
            values[f.name] = 0 if ft.count == 1 else [0] * (ft.count or 0)
        else:
            raise ValueError(f"no default value for field type {ft.name}")
    return values


def error_of(packet: Answer | WirePacket) -> ErrorReply | None:
    """The decoded error string of an error packet or answer, its numbers read in either layout (erratum
    error-arg-layout), or else straight after the NUL (a bad pad byte is the format checker's violation, not
    a reason to misjudge the error); None for a packet that is no error, or whose string reads neither
    way."""
    if packet.opcode not in ERROR_STRING_OPS:
        return None
    align: bool | None
    for align in (None, False):
        try:
            return decode_error(packet.opcode, packet.data, align_args=align)
        except CodecError:
            continue
    return None


def last_processed(packets: Sequence[WirePacket], before: WirePacket) -> int | None:
    """The request number of the last answer the server sent before ``before`` (erratum
    ``async-last-processed``): the server answers in order, so that request is the last it had
    processed when it sent ``before``."""
    number = None
    for packet in packets:
        if packet is before:
            return number
        if packet.direction == "s2c" and packet.opcode in ANSWER_OPCODES and len(packet.data) >= 2:
            number = word(packet.data)
    return number


def expect_last_processed(ctx: CaseContext, packet: WirePacket, processed: int | None) -> bool:
    """An asynchronous error carries the number of the last request processed before it, ``processed``
    (:func:`last_processed`)."""
    return ctx.expect(
        processed is not None and word(packet.data) == processed,
        clause="async-error.request-number",
        expected=f"the number of the last request processed, #{processed} (the last answered before it)",
        seen=packet,
    )


HOST_PROBES: Final = 8
HOST_PAUSE: Final = 0.002
""":func:`host_delay` sleeps this many times this long (16 ms in all, nothing in virtual time)."""


async def host_delay(ctx: CaseContext) -> float:
    """How late the case's own timers end now: the largest overshoot of a few short sleeps, in seconds
    on the run's clock (0 in virtual time).  A busy host delays a real-time target's answers and the
    case's readings alike; a check that times something allows this much for it, and says not-judged
    (:func:`not_judged_for_load`) when it cannot tell through it."""
    worst = 0.0
    for _ in range(HOST_PROBES):
        began = ctx.clock()
        await asyncio.sleep(HOST_PAUSE)
        worst = max(worst, ctx.clock() - began - HOST_PAUSE)
    return worst


def not_judged_for_load(ctx: CaseContext, reason: str) -> None:
    """A timing check that the host's delays left undecided: the case ends not-judged for ``reason``
    (which names the delays measured), unless it already found a violation, which stands (the reason
    is then a note)."""
    if ctx.recorded:
        ctx.note(f"not judged: {reason}")
    else:
        ctx.not_judged(reason)


async def settle(
    ctx: CaseContext, probe: Probe, goal: Iterable[float], *, within: float = 10.0, tol: float = 1e-3
) -> tuple[float, ...] | None:
    """Poll the joint angles every 0.1 s until they are all within ``tol`` degrees of ``goal``: the
    angles then, or None when ``within`` seconds pass first."""
    target = tuple(goal)
    deadline = ctx.clock() + within
    while True:
        joints = await read_floats(ctx, probe, "joint-angles")
        if max(abs(a - b) for a, b in zip(joints, target, strict=True)) <= tol:
            return joints
        if ctx.clock() >= deadline:
            return None
        await probe.drain(0.1)


# ------------------------------------------------------------------------------ the guide's own route
POLL_S: Final = 0.01
"""Seconds between two readings of the guide's own route (in the target's time: divided by the time
scale of a faster-than-real simulated arm)."""
SEGMENT_MASK: Final = 1 << SPEC.async_codes[AsyncCondition.SEGMENT_COMPLETED].notification_bit
"""request-notifications mask bit of segment completions."""


def extension_name(name: RequestName) -> str:
    """An extension opcode as messages name it: ``0257, request notifications, a Puma extension``."""
    op = SPEC.request(name)
    return f"{octal(op.opcode)}, {op.title[:1].lower()}{op.title[1:]}, a Puma extension"


async def ask_notifications(ctx: CaseContext, probe: Probe, mask: int = SEGMENT_MASK) -> bool:
    """Ask for the asynchronous responses of ``mask`` (request notifications, a Puma extension); whether
    the target serves it.  A refusal is no violation: the 1985 guide gives no opcode to ask for them, so
    the case goes the guide's own way (a note says so); a malformed answer is the invariant's violation."""
    answer = await probe.call("request-notifications", mask=mask)
    ctx.check(check_reply(answer.request, answer.packets))
    if answer.is_response:
        return True
    ctx.note(
        f"the target refused {extension_name('request-notifications')} ({answer}): judged with the 1985 "
        "guide's own requests, polling Joint angles (0202)"
    )
    return False


def no_wrist(answer: Answer) -> str:
    """Why a case of the wrist is not judged on a target that refused wrist version: what would judge it."""
    return (
        f"the target serves no wrist (it refused {extension_name('wrist-version')}: {answer}), and the 1985 "
        "guide gives no opcode to reach one: a server with a Cougar wrist judges it (the embedded server, "
        "manip-conform run without HOST, or manip-server --cougar sim)"
    )


def length(ctx: CaseContext, mm: float) -> float:
    """A length the suite chose in millimetres, in the unit the run takes the target's lengths in
    (``--length-unit``; the 1985 guide gives none: erratum ``units``)."""
    return mm / ctx.options.mm_per_unit


UNIT_FREE_REFUSALS: Final = frozenset({"NAP", "AWA"})
"""Refusal codes that cannot be a length unit's doing (no power, motion aborted)."""


def require_reach(ctx: CaseContext, answer: Answer, what: str) -> None:
    """Like :func:`require_response`, for a Cartesian request (a transform or an increment) the case
    sized in the run's length unit: a refusal that may be the unit's (TOR, out of reach: any code but no
    power or an abort) ends the case not-judged with a message that names ``--length-unit``."""
    ctx.check(check_reply(answer.request, answer.packets))
    if answer.is_response:
        return
    error = error_of(answer)
    code = error.error.code if error is not None else ""
    if code not in UNIT_FREE_REFUSALS:
        unit = ctx.options.length_unit
        others = "|".join(u for u in MM_PER_UNIT if u != unit)
        ctx.not_judged(
            f"the target refused {what}, sized in {unit} ({answer}"
            + (f", {code}" if code else "")
            + "): out of reach if its lengths are in another unit, which the 1985 guide does not give "
            f"(erratum units); run with --length-unit {others} to size the moves in it"
        )
    require_response(ctx, answer, what)


class Reading(NamedTuple):
    """One reading of the joint angles, at ``at`` seconds of the case's clock."""

    at: float
    joints: tuple[float, ...]


async def poll_joints(
    ctx: CaseContext,
    probe: Probe,
    *,
    within: float,
    until: Callable[[Sequence[Reading]], bool],
    every: float = POLL_S,
) -> list[Reading]:
    """Read the joint angles every ``every`` seconds until ``until`` says the readings so far are
    enough, or ``within`` seconds pass (the last reading is then the one after the limit)."""
    out: list[Reading] = []
    deadline = ctx.clock() + within
    while True:
        out.append(Reading(ctx.clock(), await read_floats(ctx, probe, "joint-angles")))
        if until(out) or out[-1].at >= deadline:
            return out
        await probe.drain(every / ctx.options.time_scale)


def near(joints: Sequence[float], goal: Sequence[float], tol: float = 1e-3) -> bool:
    """Every joint within ``tol`` degrees of ``goal``."""
    return max(abs(a - b) for a, b in zip(joints, goal, strict=True)) <= tol


async def arrival(
    ctx: CaseContext, probe: Probe, goal: Sequence[float], *, within: float = 10.0, tol: float = 1e-3
) -> float | None:
    """The end of a motion by the 1985 guide's own requests: the case's clock at the first reading of
    the joint angles within ``tol`` of ``goal``, or None when ``within`` seconds pass first."""
    readings = await poll_joints(ctx, probe, within=within, until=lambda r: near(r[-1].joints, goal, tol))
    return readings[-1].at if near(readings[-1].joints, goal, tol) else None


async def timed_move(
    ctx: CaseContext, probe: Probe, goal: Sequence[float], *, notified: bool, within: float = 10.0
) -> float:
    """Seconds from a move to ``goal`` (set joint angles) to its end: its segment-completed response
    when notifications are on (``notified``), else its arrival seen by polling the joint angles.  The
    case skips when the move is refused, and ends not-judged when no end is seen within ``within``
    seconds (the cases of segment completion and of motion judge a missing one)."""
    start = ctx.clock()
    answer = await probe.call("set-joint-angles", joints=list(goal))
    require_response(ctx, answer, "a small move accepted")
    segment = word(answer.data, 2)
    if not notified:
        end = await arrival(ctx, probe, goal, within=within)
        if end is None:
            ctx.not_judged(
                f"the arm did not reach {list(goal)} within {within:g} s, so no move was timed "
                "(server.motion.queued-segments judges where a motion ends: motion.ends-at-rest)"
            )
        return end - start
    while (packet := await probe.next_packet(within)) is not None:
        if completed_segment(packet) == segment:
            return ctx.clock() - start
    ctx.not_judged(
        f"the case times moves by their segment-completed reports; none came for segment {segment} "
        "(server.async.segment-completed judges that)"
    )


async def expect_here_served(ctx: CaseContext, probe: Probe, expected: str) -> None:
    """Here must be served normally, with its transform (after a discarded packet, for example)."""
    again = await probe.call("here")
    ctx.expect_response(
        again, clause="free-joint.awaits-next-packet", expected=expected, min_size=DONE_SIZE + 1
    )


GUARDS: Final = 16
"""Guards a Cougar holds at once (Part III §B.9)."""


async def clear_guards(probe: Probe) -> None:
    """Clear every wrist guard, if the target serves clear-guard.  Guards live in the wrist, not in the
    connection (erratum ``server-robot``): one an earlier session set would trip this case's moves.

    Cougar checks its guards before it reads new commands in the same tick (GUTS: GUARDM, then COMINT,
    Part III B.6), so a guard may still trip on the tick the clears arrive.  A request the wrist itself
    answers (its version) comes back only after they were read; the caller's enable-power then clears
    the abort such a last trip caused."""
    for index in range(GUARDS):
        answer = await probe.call("clear-guard", index=index)
        if not answer.is_response:
            return  # no wrist, or no such operation: nothing to clear
    await probe.call("wrist-version")


async def power_on(ctx: CaseContext, probe: Probe) -> None:
    """Clear leftover wrist guards, then enable high power (it also clears an abort); the case is not
    judged when the target refuses (``server.reply.enable-power`` judges the answer)."""
    await clear_guards(probe)
    answer = await probe.call("enable-power")
    require_response(ctx, answer, "arm power (enable high power answered with done)")


def expect_refusal(
    ctx: CaseContext,
    answer: Answer,
    *,
    clause: str,
    severities: tuple[str, ...] = ("C",),
    codes: tuple[str, ...] = (),
    what: str,
) -> ErrorReply | None:
    """The answer must be a non-fatal error with one of ``severities`` (and, when given, one of
    ``codes``; the codes are the 1985 guide's where it names them)."""
    wanted = f"a non-fatal error (0202) of severity {'/'.join(severities)}" + (
        f" and code {'/'.join(codes)}" if codes else ""
    )
    if not ctx.expect_opcode(
        answer, ServerOp.NON_FATAL_ERROR, clause=clause, expected=f"{wanted} for {what}"
    ):
        return None  # a weaker clause than MUST: recorded, and there is no error string to judge
    error = error_of(answer)
    if error is None:
        ctx.check(check_error_packet(answer.first))  # what is wrong with the string: the invariant's
        ctx.fail(
            f"the error string for {what} does not decode",
            clause=clause,
            expected=f"{wanted} for {what}",
            seen=showing(answer, answer.data.hex()),
        )
    ctx.expect(
        error.error.severity in severities,
        clause=clause,
        expected=f"{wanted} for {what}",
        seen=showing(answer, repr(error.error.render())),
    )
    if codes:
        ctx.expect(
            error.error.code in codes,
            clause=clause,
            expected=f"{wanted} for {what}",
            seen=showing(answer, repr(error.error.render())),
        )
    return error


def expect_error_numbers(
    ctx: CaseContext,
    answer: Answer,
    error: ErrorReply | None,
    wanted: Iterable[Iterable[int]],
    *,
    what: str,
) -> None:
    """Clause ``error-string.arg-values``: the numbers of ``error`` must be one of the ``wanted`` tuples
    (erratum ``error-arg-values``: each is what the request provoked); an error without numbers is not
    judged here."""
    if error is None or not error.error.args:
        return
    choices = {tuple(w) for w in wanted}
    args = error.error.args
    wanted_text = " or ".join(str(list(c)) for c in sorted(choices))
    ctx.expect(
        args in choices,
        clause="error-string.arg-values",
        expected=f"the numbers {wanted_text} for {what}",
        seen=showing(answer, f"{list(args)} in {error.error.render()!r}"),
    )


def out_of_range_mask(angles: Iterable[float], limits: JointLimits) -> int:
    """The joint mask (bit 0 = joint 1) of the ``angles`` outside ``limits``, as JOR's $ carries it."""
    mask = 0
    for i, (q, lo, hi) in enumerate(zip(angles, limits.lower, limits.upper, strict=True)):
        if not lo <= q <= hi:
            mask |= 1 << i
    return mask


@dataclass(frozen=True)
class TargetArm:
    """What the cases assume about the target's arm: its joint limits (from describe self's
    ``:joint-limits`` when it has them, else the PUMA 600's) and degrees of freedom."""

    limits: JointLimits = PUMA600.limits
    declared: bool = False
    """The limits came from the target itself."""
    dof: int = 6
    ready: Joints = PUMA600.ready
    operations: frozenset[int] | None = None
    """The opcodes describe self lists under :operations (None: no usable list)."""
    stated_ready: tuple[float, ...] | None = None
    """The joint angles describe self states as :ready-position (None: none, or not one number per
    degree of freedom)."""
    ready_value: LispValue | None = None
    """The :ready-position value as describe self gave it, usable or not (None: not given)."""
    described: bool = False
    """Describe self answered with a whole, readable description (the values above may come from it)."""


def _number(value: LispValue) -> float | None:
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else None


def stated_limits(value: LispValue) -> JointLimits | None:
    """The joint limits of a ``:joint-limits`` value (six (lower upper) pairs), or None."""
    if not isinstance(value, list) or len(value) != 6:
        return None
    lower: list[float] = []
    upper: list[float] = []
    for pair in value:
        if not isinstance(pair, list) or len(pair) != 2:
            return None
        lo, hi = _number(pair[0]), _number(pair[1])
        if lo is None or hi is None:
            return None
        lower.append(lo)
        upper.append(hi)
    try:
        return JointLimits(tuple(lower), tuple(upper))
    except ValueError:
        return None


async def describe_target(ctx: CaseContext, probe: Probe) -> TargetArm:
    """Ask describe self for the arm's limits; anything missing or odd falls back to the PUMA 600."""
    answer = await probe.call("describe-self")
    if not answer.is_response or not answer.terminated:
        return TargetArm()
    entries, _ = parse_description(multi_text(answer.packets))
    if entries is None:
        return TargetArm()
    limits = stated_limits(entries["joint-limits"]) if "joint-limits" in entries else None
    dof_value = entries.get("degrees-of-freedom")
    dof = int(dof_value) if isinstance(dof_value, int) and dof_value > 0 else 6
    listed = description_operations(entries)
    operations = frozenset(listed) if listed else None
    value = entries.get("ready-position")
    ready = _stated_ready(value, dof)
    if limits is None:
        ctx.note("describe self gives no usable :joint-limits; assuming the PUMA 600's")
        return TargetArm(
            dof=dof, operations=operations, stated_ready=ready, ready_value=value, described=True
        )
    return TargetArm(
        limits=limits,
        declared=True,
        dof=dof,
        operations=operations,
        stated_ready=ready,
        ready_value=value,
        described=True,
    )


def _stated_ready(value: LispValue | None, dof: int) -> tuple[float, ...] | None:
    """A :ready-position value as joint angles, when it is one number per degree of freedom."""
    if not isinstance(value, list) or len(value) != dof:
        return None
    numbers = [_number(v) for v in value]
    return tuple(v for v in numbers if v is not None) if None not in numbers else None


def reply_view(answer: Answer) -> AnswerSummary:
    """The model's view of an answer (a RESPONSE, or the decoded error string of an error)."""
    first = answer.first
    if first.opcode == ServerOp.RESPONSE:
        op = SPEC.requests.get(answer.request.opcode)
        segment = None
        if op is not None and op.response.form == "segment" and len(first.data) == 4:
            segment = word(first.data, 2)
        return AnswerSummary(True, empty=len(first.data) == 2, segment=segment)
    decoded = error_of(first)
    return AnswerSummary(False, error=None if decoded is None else decoded.error)


def must(violations: Iterable[Violation]) -> list[Violation]:
    """The violations of a MUST clause."""
    return [v for v in violations if v.level == "MUST"]


class Evidence(CarriesViolation, AssertionError):  # noqa: N818 - a failed example, not an error of the suite
    """A failed example: its :class:`~manip.conformance.judge.violation.Violation` (``.violation``), and
    the packets that showed it.

    ``invariant``: the suite invariant that found it (a checker's violation, a probe's failure), passed
    on to ``ctx.fail_with`` so that a clause the case does not declare is attributed to it."""

    # ``args`` is set instead of calling ``super().__init__``: tests/support/clause_scan.py binds the
    # positional arguments of any ``__init__`` call here to this signature, whose first parameter is a clause.
    def __init__(
        self,
        clause: str,
        message: str,
        expected: str,
        actual: str,
        data: bytes = b"",
        packets: Iterable[WirePacket] = (),
        example: Iterable[WirePacket] = (),
        drawn: str = "",
        invariant: str | None = None,
    ) -> None:
        self.violation = Violation(
            message, clause, expected=expected, actual=actual, data=data, invariant=invariant
        )
        self.args = (str(self.violation),)  # the exception's message (no super() call: see below)
        self.packets = list(packets)
        self.example = list(example)
        """Every packet of the example that failed, both ways (set by the case's runner; ``packets``
        are the ones among them that show the failure)."""
        self.drawn = drawn
        """What Hypothesis drew for that example, as the report shows it (set by the case's runner)."""

    @classmethod
    def of(cls, violation: Violation, packets: Iterable[WirePacket] = ()) -> Evidence:
        """A violation a checker found (the transcript invariant's checkers)."""
        evidence = cls("", "", "", "", packets=packets)
        evidence.violation = replace(violation, invariant=TRANSCRIPT.name)
        evidence.args = (str(evidence.violation),)
        return evidence

    @property
    def culprit(self) -> WirePacket | None:
        """The packet the failure is about: the violation's own, else the first server packet among those
        that show it (what the server got wrong), else the first of them."""
        if self.violation.packet is not None:
            return self.violation.packet
        answers = [p for p in self.packets if p.direction == "s2c" and not p.is_close]
        shown = answers or self.packets
        return shown[0] if shown else None
