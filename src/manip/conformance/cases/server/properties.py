"""Property-based cases: Hypothesis draws requests from the spec tables and checks what comes back.

* ``property.requests.well-formed``: any well-formed request of the allowed hazard classes gets exactly
  one answer of the shape the spec gives its opcode (or a well-formed error), echoing its number;
* ``property.kinematics.round-trip``: solve backwards, then solve forwards from other angles, then
  backwards again: the two transforms are the same pose (joint angles may differ: an arm has several
  solutions), within :data:`POSE_TOL_MM` and :data:`POSE_TOL_DEG` (erratum ``pose-equivalence``);
* ``property.floats.round-trip``: set joint angles, read them back once the arm stands: each angle
  comes back within :data:`FLOAT_TRIP_ULPS` units of the 24th significand bit (erratum
  ``float-round-trip``);
* ``property.segments.numbering``: accepted motion requests get segment numbers one apart (SHOULD).

Each case runs its Hypothesis test in a worker thread that drives the probe on the runner's loop
(:mod:`manip.conformance.suite.bridge`), seeded with the case's seed, ``ctx.max_examples`` examples.  A
failure is shrunk (within a time budget) and reported with what was drawn for the shrunk example and
every packet of it, numbered and decoded (:mod:`manip.conformance.output.packet_text`).
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any, Final

from hypothesis import given, reject, seed
from hypothesis import strategies as st
from hypothesis.errors import Flaky

from manip.arm.kinematics import Joints
from manip.arm.transform import FLOAT_ROTATION_TOL, Transform
from manip.codecs.errors import CodecError
from manip.codecs.messages import encode_request
from manip.conformance.cases._support import Evidence, describe_target, floats, must, reply_view
from manip.conformance.judge.checks import ANSWER_OPCODES, WirePacket, check_reply, completed_segment
from manip.conformance.judge.diagnosis import float_payload, floats_diagnosis
from manip.conformance.output.packet_text import packet_listing, show_value
from manip.conformance.suite.bridge import (
    DEFAULT_SHRINK_BUDGET,
    Bridge,
    FailureLog,
    StopRun,
    connect_fresh,
    hypothesis_settings,
    run_in_worker,
)
from manip.conformance.suite.case import CaseFailure, case
from manip.conformance.suite.context import DEFAULT_REPLY_TIMEOUT, Answer, CaseContext, Probe
from manip.conformance.suite.invariants import TRANSCRIPT
from manip.conformance.suite.strategies import (
    f_ulp,
    joints_near,
    joints_out_of_range,
    joints_within,
    requests_of,
    valid_requests,
)
from manip.conformance.suite.world import CaseNotJudged
from manip.spec import SPEC, RequestName, RequestOpcode
from manip.spec.constants import AsyncCondition, ServerOp

__all__ = ["FLOAT_TRIP_ULPS", "POSE_TOL_DEG", "POSE_TOL_MM"]

#: Pose equivalence (erratum pose-equivalence): two transforms are the same pose when their positions
#: are within this many millimetres...
POSE_TOL_MM: Final = 0.05
#: ... and the rotation between them is at most this many degrees.
POSE_TOL_DEG: Final = 0.05
#: A float read back may differ from the one written by this many units in its 24th significand bit
#: (erratum float-round-trip): one re-rounding on the server's side each way.
FLOAT_TRIP_ULPS: Final = 2
#: How far (deg) the float round trip moves each joint from where the case found the arm.
TRIP_STEP_DEG: Final = 0.25
#: Each example waits for a move to end (about a second on the reference arm, whose blends take 0.3 s
#: at full speed), so this case runs ``max_examples / TRIP_EXAMPLE_DIVISOR`` examples (at least 3).
TRIP_EXAMPLE_DIVISOR: Final = 5
POLL_PERIOD: Final = 0.02
SETTLE_POLLS: Final = 5
"""Identical joint-angle readings in a row that mean the arm stands still (when the target does not
send segment-completed responses)."""
SEGMENT_MASK: Final = 1 << SPEC.async_codes[AsyncCondition.SEGMENT_COMPLETED].notification_bit
SETTLE_LIMIT: Final = 5.0
PROPERTY_BUDGET: Final = 45.0
"""Seconds (on the run's clock) after which a property case draws no new example."""
SLOWEST_STEP: Final = DEFAULT_REPLY_TIMEOUT + max(op.answer_within or 0.0 for op in SPEC.requests.values())
"""The longest one step of an example may wait: a reply to a request whose answer waits for the arm
or the wrist (the spec's ``answer_within``) after the reply timeout."""
PROPERTY_DEADLINE: Final = PROPERTY_BUDGET + SLOWEST_STEP + DEFAULT_SHRINK_BUDGET
"""A property case's deadline: its budget, then the step under way when the budget ran out, then
shrinking (so the budget, not the deadline, ends a case whose examples are slow by the spec)."""


# ------------------------------------------------------------------------------------- machinery
class _Session:
    """The probe a property case's examples share; a new connection when the last one ended."""

    def __init__(self, ctx: CaseContext, bridge: Bridge) -> None:
        self.ctx = ctx
        self.bridge = bridge
        self._probe: Probe | None = None

    @property
    def probe(self) -> Probe:
        if self._probe is None or self._probe.closed or self._probe.end_reason is not None:
            self._probe = self.bridge.call(connect_fresh(self.ctx))
        return self._probe

    def ask(self, opcode: int | RequestName, data: bytes = b"") -> Answer:
        """Send one request and take its whole answer; no answer at all is an :class:`Evidence`."""
        probe = self.probe
        try:
            return self.bridge.call(_ask(probe, opcode, data))
        except CaseFailure as exc:
            raise Evidence(
                exc.clause or "request.one-reply",
                exc.message,
                exc.expected,
                exc.actual,
                exc.data,
                list(probe.packets[-4:]),
                invariant=TRANSCRIPT.name,  # the probe's own failures (no answer, no connection)
            ) from None

    def call(self, name: RequestName, **values: Any) -> Answer:
        return self.ask(name, encode_request(name, **values))


async def _ask(probe: Probe, opcode: int | RequestName, data: bytes) -> Answer:
    code = opcode if isinstance(opcode, int) else SPEC.request(opcode).opcode
    number = await probe.request(code, data)
    op = SPEC.requests.get(code)
    if op is not None and op.response.form == "multi":
        return await probe.replies_until_empty(number)
    return await probe.reply(number)


def _check_answer(answer: Answer) -> None:
    """The MUST violations the generic reply checker finds, as a failed example."""
    found = must(check_reply(answer.request, answer.packets))
    if found:
        raise Evidence.of(found[0], [answer.request, *answer.packets])


def _decode_floats(answer: Answer, what: str, clause: str | None) -> tuple[float, ...]:
    """The floats of a data reply.  A malformed reply is the transcript invariant's evidence; a refusal
    breaks ``clause``, or leaves the case not judged when it only needs the values (``clause`` None)."""
    _check_answer(answer)
    if not answer.is_response:
        if clause is None:
            raise CaseNotJudged(f"the case needs {what}, which the target refused: {answer}")
        raise Evidence(
            clause,
            f"{what} was refused",
            f"a normal reply to {what}",
            str(answer),
            answer.data,
            [answer.request, *answer.packets],
        )
    try:
        return floats(answer)
    except CodecError as exc:
        raise Evidence(
            exc.clause if exc.clause in TRANSCRIPT.clauses else "response.data-layout",
            f"{what} reply does not decode: {exc}",
            f"the {what} layout",
            str(exc),
            answer.data,
            [answer.request, *answer.packets],
            invariant=TRANSCRIPT.name,
        ) from None


def _size(evidence: Evidence) -> int:
    return sum(len(p.data) + 8 for p in evidence.packets)


def _drawn(args: tuple[Any, ...]) -> str:
    """The arguments of an example as a person reads them (requests by name and octal opcode)."""
    return "; ".join(_show_drawn(a) for a in args)


def _show_drawn(value: Any) -> str:
    if isinstance(value, RequestOpcode):
        return f"{value.name} 0{value.opcode:o}"
    if isinstance(value, (bytes, bytearray)):
        return f"data {value.hex(' ')}" if value else "no data"
    if isinstance(value, tuple) and value and isinstance(value[0], RequestOpcode):
        return ", ".join(_show_drawn(v) for v in value)  # a request: its opcode, then its data
    if isinstance(value, (tuple, list)):
        return "(" + ", ".join(_show_drawn(v) for v in value) + ")"
    return show_value(value)


def _example_text(failure: Evidence) -> str:
    """The shrunk example: what was drawn, then its packets numbered and decoded (``>``: the failure's)."""
    text = f"\nshrunk example: {failure.drawn}" if failure.drawn else ""
    if failure.example:
        inside = {id(p) for p in failure.example}
        before = [p for p in failure.packets if id(p) not in inside]  # e.g. the previous segment's
        text += "\npackets of the example (> the ones that show the failure"
        text += f"; the first {len(before)} came before the example):" if before else "):"
        listing = packet_listing([*before, *failure.example], marked=failure.packets)
    else:
        text += "\npackets:" if failure.packets else ""
        listing = packet_listing(failure.packets)
    return text + "".join(f"\n{line}" for line in listing)


def _example_packets(failure: Evidence) -> list[WirePacket]:
    """The packets of the shrunk example for the case's packet log (with those of its setup before it);
    the whole failing exchange when the example was not recorded apart."""
    if not failure.example:
        return list(failure.packets)
    inside = {id(p) for p in failure.example}
    return [*(p for p in failure.packets if id(p) not in inside), *failure.example]


def _first_evidence(group: BaseException) -> Evidence | None:
    if isinstance(group, Evidence):
        return group
    for inner in getattr(group, "exceptions", ()):
        found = _first_evidence(inner)
        if found is not None:
            return found
    return None


Example = Callable[..., None]


async def run_property(
    ctx: CaseContext,
    build: Callable[[_Session], tuple[Example, Sequence[st.SearchStrategy[Any]]]],
    *,
    max_examples: int | None = None,
    budget: float = PROPERTY_BUDGET,
) -> None:
    """Run one Hypothesis property against the target and turn its verdict into the case's.

    ``build`` gets the shared session and returns the example function and the strategies of its
    arguments; the example raises :class:`Evidence` when the property fails."""
    log: FailureLog[Evidence] = FailureLog()
    examples = ctx.max_examples if max_examples is None else max_examples
    stats = {"examples": 0}

    def work(bridge: Bridge) -> tuple[Evidence | None, str]:
        session = _Session(ctx, bridge)
        try:
            body, strategies = build(session)
        except Evidence as exc:
            return exc, "(while preparing the examples)"

        def example(args: tuple[Any, ...]) -> None:
            stats["examples"] += 1
            start = len(ctx.transcript)
            try:
                body(*args)
            except Evidence as exc:
                exc.example, exc.drawn = list(ctx.transcript[start:]), _drawn(args)
                log.add(exc, _size(exc))
                bridge.failure_seen()
                raise

        test = seed(ctx.seed)(hypothesis_settings(examples)(given(st.tuples(*strategies))(example)))
        try:
            test()
        except Evidence as exc:
            return exc, ""  # Hypothesis's notes show Python objects: the report shows the packets
        except Flaky as exc:
            found = _first_evidence(exc) or log.best
            if found is None:
                ctx.note(f"Hypothesis: {type(exc).__name__}, but no failure was seen")
                return None, ""
            return (
                found,
                f"the failure did not reproduce on every replay (flaky target?); {type(exc).__name__}",
            )
        except StopRun:
            if log.best is not None:
                return (
                    log.best,
                    f"shrinking stopped after its time budget ({log.count} failing examples seen)",
                )
            if bridge.stopped_by_budget:
                ctx.note(f"stopped after its {budget:g} s budget, {stats['examples']} examples, no failure")
            return None, ""
        return None, ""

    failure, notes = await run_in_worker(work, budget=budget)
    ctx.note(f"{stats['examples']} examples run (seed {ctx.seed})")
    if failure is not None:
        actual = failure.actual
        if notes:
            actual += f"\n{notes}"
        actual += _example_text(failure)
        ctx.show_packets(_example_packets(failure))
        culprit = failure.culprit
        ctx.fail_with(replace(failure.violation, actual=actual, packet=culprit))


# ------------------------------------------------------------------------------- well-formed replies
_FORM_CLAUSES: Final = {
    "done": "response.done-empty",
    "data": "response.data-layout",
    "segment": "response.segment-number",
    "multi": "multi.terminated-by-empty",
}


def _answer_clauses(op: RequestOpcode, answer: Answer) -> tuple[str, ...]:
    """The clauses the reply checker judged on ``answer`` to a request of ``op``: those of every answer,
    and those of its form (a normal reply of the opcode's shape, or an error string)."""
    common = ("request.one-reply", "response.echoes-request-number", "response.server-opcodes")
    if answer.is_error:
        return (*common, "error-string.format", "error-string.severity", "error-string.code")
    return (*common, _FORM_CLAUSES[op.response.form])


@case(
    "property.requests.well-formed",
    clauses=[
        "request.one-reply",
        "response.echoes-request-number",
        "response.server-opcodes",
        "response.done-empty",
        "response.data-layout",
        "response.segment-number",
        "multi.terminated-by-empty",
        "error-string.format",
        "error-string.severity",
        "error-string.code",
        "error.fatal-then-close",
        "free-joint.replies",
    ],
    technique="property",
    hazard="config",
    deadline=PROPERTY_DEADLINE,
)
async def well_formed_replies(ctx: CaseContext) -> None:
    """Random well-formed requests (of the allowed hazard classes) get one well-formed answer each."""
    ops = requests_of(ctx.options.allowed_hazards)
    free_joint = SPEC.request("free-joint").opcode

    def build(session: _Session) -> tuple[Example, Sequence[st.SearchStrategy[Any]]]:
        def body(request: tuple[Any, bytes]) -> None:
            op, data = request
            if session.probe.arm_wait(op.opcode) > SLOWEST_STEP * ctx.options.deadline_scale:
                # An earlier example set a crawling speed or queued long motion: this answer may
                # conformingly take longer than any case can wait (erratum answer-allowance).
                reject()
            answer = session.ask(op.opcode, data)
            _check_answer(answer)
            ctx.exercised(*_answer_clauses(op, answer))
            if answer.opcode == ServerOp.FATAL_ERROR:
                closed = session.bridge.call(session.probe.wait_closed())
                if not closed:
                    raise Evidence(
                        "error.fatal-then-close",
                        "the connection stayed open after a fatal error",
                        "CLS after the fatal error",
                        "the connection still open",
                        answer.data,
                        [answer.request, *answer.packets],
                    )
                ctx.exercised("error.fatal-then-close")
                return
            if op.opcode == free_joint and answer.is_response:
                # the joint is free until the next packet, which is discarded and answered with done
                release = session.call("joint-angles")
                if not (release.is_response and len(release.data) == 2):
                    raise Evidence(
                        "free-joint.replies",
                        "the packet after free joint was not answered with an empty done",
                        "an empty done",
                        str(release),
                        release.data,
                        [answer.request, answer.first, release.request, *release.packets],
                    )
                ctx.exercised("free-joint.replies")

        return body, [valid_requests(ops)]

    await run_property(ctx, build)


# ------------------------------------------------------------------------------------- kinematics
def _pose(values: Sequence[float], answer: Answer) -> Transform:
    try:
        return Transform.from_floats(values, tol=FLOAT_ROTATION_TOL)
    except ValueError as exc:
        raise Evidence(
            "solve-backwards.data",
            f"solve backwards returned no rigid transform: {exc}",
            "a transform whose N, O, A are a rotation",
            repr(values),
            answer.data,
            [answer.request, *answer.packets],
        ) from None


@case(
    "property.kinematics.round-trip",
    clauses=["solve-backwards.data", "solve-forwards.data", "solve-forwards.errors"],
    technique="property",
    hazard="read-only",
    deadline=PROPERTY_DEADLINE,
)
async def kinematics_round_trip(ctx: CaseContext) -> None:
    """Solve backwards, forwards from other angles, backwards again: the same pose (erratum
    pose-equivalence), and solve forwards never refuses a transform made from in-range angles."""
    probe = await ctx.connect()
    arm = await describe_target(ctx, probe)
    await probe.close()
    unit = ctx.options.length_unit
    tol = POSE_TOL_MM / ctx.options.mm_per_unit  # the target's lengths are in --length-unit

    def build(session: _Session) -> tuple[Example, Sequence[st.SearchStrategy[Any]]]:
        def body(q: Joints, near: Joints) -> None:
            first = session.call("solve-backwards", joints=list(q))
            t1 = _pose(_decode_floats(first, "solve backwards", "solve-backwards.data"), first)
            ctx.exercised("solve-backwards.data")
            second = session.call("solve-forwards", transform=list(t1.to_floats()), current=list(near))
            if not second.is_response and not arm.declared:
                return  # the target's own limits are unknown: a TOR may be right
            q2 = _decode_floats(
                second, "solve forwards of a transform made from in-range joint angles", "solve-forwards.data"
            )
            bad = arm.limits.violations(q2, tol=1e-3)
            ctx.exercised("solve-forwards.errors")
            if bad:
                raise Evidence(
                    "solve-forwards.errors",
                    f"solve forwards returned joint(s) {bad} out of range",
                    "joint angles within the limits (TOR when there are none)",
                    repr(q2),
                    second.data,
                    [second.request, second.first],
                )
            third = session.call("solve-backwards", joints=list(q2))
            t2 = _pose(_decode_floats(third, "solve backwards", "solve-backwards.data"), third)
            distance = t1.distance(t2)
            ctx.exercised("solve-forwards.data")
            if distance.translation_mm > tol or distance.rotation_deg > POSE_TOL_DEG:
                raise Evidence(
                    "solve-forwards.data",
                    "solve forwards returned angles that do not reach the transform",
                    f"the same pose within {tol:.4g} {unit} and {POSE_TOL_DEG} deg",
                    f"off by {distance.translation_mm:.4g} {unit} and {distance.rotation_deg:.4g} deg: "
                    f"angles {q} gave {t1!r}; solve forwards from {near} gave {q2}, "
                    f"whose transform is {t2!r}",
                    second.data,
                    [first.request, first.first, second.request, second.first, third.request, third.first],
                )

        strategy = joints_within(arm.limits, margin=1.0)
        return body, [strategy, strategy]

    await run_property(ctx, build)


# ------------------------------------------------------------------------------------- floats
def _close_enough(got: Sequence[float], sent: Sequence[float]) -> bool:
    return all(abs(g - s) <= FLOAT_TRIP_ULPS * f_ulp(s) for g, s in zip(got, sent, strict=True))


async def _segment_done(probe: Probe, segment: int, seen: int) -> bool:
    """Wait (up to :data:`SETTLE_LIMIT`) for the segment-completed response of ``segment``; the
    unsolicited packets from index ``seen`` on are looked at first."""

    def done(packet: WirePacket) -> bool:
        return completed_segment(packet) == segment

    if any(done(p) for p in probe.unsolicited[seen:]):
        return True
    loop = asyncio.get_running_loop()
    end = loop.time() + SETTLE_LIMIT
    while (left := end - loop.time()) > 0:
        packet = await probe.next_packet(left)
        if packet is None:
            return False
        if packet.opcode in ANSWER_OPCODES:
            probe.push_back(packet)  # not ours to take: the transcript check will judge it
            return False
        if done(packet):
            return True
    return False


async def _settle(
    probe: Probe, goal: Sequence[float], segment: int | None, seen: int
) -> tuple[Answer, tuple[float, ...]]:
    """The joint angles once the arm stands: after the segment-completed response when notifications
    work, else by polling until they match ``goal`` or stop changing (or :data:`SETTLE_LIMIT` passes)."""
    if segment is not None and await _segment_done(probe, segment, seen):
        answer = await probe.call("joint-angles")
        try:
            return answer, floats(answer) if answer.is_response else ()
        except CodecError:
            return answer, ()
    loop = asyncio.get_running_loop()
    end = loop.time() + SETTLE_LIMIT
    previous: bytes | None = None
    same = 0
    while True:
        answer = await probe.call("joint-angles")
        if not answer.is_response:
            return answer, ()
        try:
            got = floats(answer)
        except CodecError:
            return answer, ()
        if _close_enough(got, goal):
            return answer, got
        same = same + 1 if answer.data[2:] == previous else 0
        previous = answer.data[2:]
        if same >= SETTLE_POLLS or loop.time() > end:
            return answer, got
        await asyncio.sleep(POLL_PERIOD)


@case(
    "property.floats.round-trip",
    clauses=["float.format", "joint-angles.reply", "response.segment-number", "motion.no-power"],
    technique="property",
    hazard="motion",
    deadline=PROPERTY_DEADLINE,
    extensions=["request-notifications"],
)
async def floats_round_trip(ctx: CaseContext) -> None:
    """Set joint angles, read them back when the arm stands: each float survives the trip within
    FLOAT_TRIP_ULPS units of its 24th bit (erratum float-round-trip)."""
    probe = await ctx.connect()
    arm = await describe_target(ctx, probe)
    await probe.close()

    def build(session: _Session) -> tuple[Example, Sequence[st.SearchStrategy[Any]]]:
        power = session.call("enable-power")
        _check_answer(power)
        notified = session.call("request-notifications", mask=SEGMENT_MASK)
        _check_answer(notified)
        start = _decode_floats(session.call("joint-angles"), "joint angles", None)
        home = tuple(
            min(max(q, lo + 1.0), hi - 1.0)
            for q, lo, hi in zip(start, arm.limits.lower, arm.limits.upper, strict=True)
        )

        def body(goal: Joints) -> None:
            seen = len(session.probe.unsolicited)
            answer = session.call("set-joint-angles", joints=list(goal))
            _check_answer(answer)
            if not answer.is_response:  # powered, in range, not aborted: nothing may refuse it
                raise Evidence(
                    "motion.no-power",
                    "an in-range set joint angles was refused on a powered arm",
                    "a segment number",
                    str(answer),
                    answer.data,
                    [answer.request, answer.first],
                )
            ctx.exercised("motion.no-power", "response.segment-number")
            segment = reply_view(answer).segment if notified.is_response else None
            settled, got = session.bridge.call(_settle(session.probe, goal, segment, seen))
            _check_answer(settled)
            ctx.exercised("float.format", "joint-angles.reply")
            if not got or not _close_enough(got, goal):
                worst = (
                    max(range(len(goal)), key=lambda i: abs(got[i] - goal[i]) / f_ulp(goal[i])) if got else 0
                )
                cause = floats_diagnosis(float_payload(SPEC.request("joint-angles"), settled.data), goal)
                raise Evidence(
                    "float.format",
                    "joint angles read back differ from those set by more than the float precision"
                    + (f"; {cause}" if cause else ""),
                    f"{list(goal)} (each within {FLOAT_TRIP_ULPS} units of the 24th bit)",
                    f"{list(got)}; joint {worst + 1}: sent {goal[worst]!r}, got "
                    f"{got[worst] if got else 'nothing'!r}",
                    settled.data,
                    [answer.request, answer.first, settled.request, settled.first],
                )

        return body, [joints_near(home, arm.limits, step=TRIP_STEP_DEG)]

    await run_property(ctx, build, max_examples=max(3, ctx.max_examples // TRIP_EXAMPLE_DIVISOR))


# ------------------------------------------------------------------------------------- segments
@case(
    "property.segments.numbering",
    clauses=["segment.number-increases"],
    technique="property",
    hazard="motion",
    deadline=PROPERTY_DEADLINE,
)
async def segment_numbering(ctx: CaseContext) -> None:
    """Accepted motion requests get segment numbers one apart, refused ones take none."""
    probe = await ctx.connect()
    arm = await describe_target(ctx, probe)
    await probe.close()

    def build(session: _Session) -> tuple[Example, Sequence[st.SearchStrategy[Any]]]:
        _check_answer(session.call("enable-power"))
        start = _decode_floats(session.call("joint-angles"), "joint angles", None)
        home = tuple(
            min(max(q, lo + 1.0), hi - 1.0)
            for q, lo, hi in zip(start, arm.limits.lower, arm.limits.upper, strict=True)
        )
        last: list[Answer] = []

        def body(goals: list[tuple[bool, Joints]]) -> None:
            for in_range, goal in goals:
                answer = session.call("set-joint-angles", joints=list(goal))
                _check_answer(answer)
                view = reply_view(answer)
                if view.segment is None:
                    if in_range and view.error is not None and view.error.code in ("AWA", "NAP"):
                        _check_answer(session.call("enable-power"))
                    continue
                if last:
                    before = reply_view(last[-1]).segment
                    assert before is not None
                    ctx.exercised("segment.number-increases")
                    if view.segment != (before + 1) & 0xFFFF:
                        raise Evidence(
                            "segment.number-increases",
                            f"segment {view.segment} follows segment {before}",
                            f"segment {(before + 1) & 0xFFFF}",
                            f"segment {view.segment}",
                            answer.data,
                            [last[-1].request, last[-1].first, answer.request, answer.first],
                        )
                last[:] = [answer]

        near = joints_near(home, arm.limits, step=TRIP_STEP_DEG).map(lambda q: (True, q))
        far = joints_out_of_range(arm.limits, start=home).map(lambda qb: (False, qb[0]))
        return body, [st.lists(st.one_of(near, near, far), min_size=2, max_size=6)]

    await run_property(ctx, build)
