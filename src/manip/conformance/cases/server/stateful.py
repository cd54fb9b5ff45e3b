"""The stateful case: a Hypothesis rule-based state machine drives the target through random
sequences of requests while :class:`~manip.conformance.judge.model.ProtocolModel` says what each may answer.

Rules are requests (power on and off, moves of every kind, the ready position, set speed in and out
of range, request notifications, reset abort, here, joint angles, solve backwards, free joint and the
packet after it, hand, set configuration, describe self) and malformed ones (unknown opcodes, wrong
lengths, reserved-operand floats), plus a compound rule that makes the move process abort (a long move,
then power killed while it runs) and a rule that only waits, letting segments finish and asynchronous
packets arrive.  With ``--target hardware`` and no ``--allow-motion`` the motion and power rules are
left out (their preconditions are false) and malformed requests use read-only and config opcodes only.

Invariants, checked at every step:

* exactly one answer per request (a multi-packet reply counts as one), echoing its number, within the
  reply timeout; no answer arrives while nothing is outstanding;
* the answer is one the model allows: the refusals NAP, AWA, JOR (joint angles), TOR (transforms) and
  command errors exactly when the model says (see the model's docstring), and the normal reply of the
  opcode's shape otherwise;
* asynchronous responses only when asked for (the 0257 mask in force after the request they name),
  of a queued segment, each once, in queue order; asynchronous errors well-formed;
* and at the end of each run the whole recording passes
  :func:`~manip.conformance.judge.checks.check_transcript` (MUST clauses).

A failure is shrunk (within a time budget) and reported as the list of requests that shows it (opcode,
name, data in hex, the waits in between) with a Python line that replays it: :func:`replay`.
"""

from __future__ import annotations

import asyncio
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace
from typing import Any, ClassVar, Final

from hypothesis import seed
from hypothesis import strategies as st
from hypothesis.errors import Flaky
from hypothesis.stateful import (
    Bundle,
    RuleBasedStateMachine,
    initialize,
    precondition,
    rule,
    run_state_machine_as_test,
)

from manip.arm.kinematics import Joints, forward
from manip.codecs.errors import CodecError
from manip.codecs.messages import decode_async, encode_request
from manip.conformance.cases._support import (
    Evidence,
    TargetArm,
    describe_target,
    error_of,
    floats,
    must,
    reply_view,
)
from manip.conformance.judge.checks import (
    ANSWER_OPCODES,
    WirePacket,
    check_async_packet,
    check_error_packet,
    check_reply,
    check_server_opcode,
    check_transcript,
    describe,
    word,
)
from manip.conformance.judge.model import (
    MODEL_CLAUSES,
    AnswerSummary,
    DistinctViolations,
    Expectation,
    ProtocolModel,
)
from manip.conformance.judge.violation import Violation
from manip.conformance.output.packet_text import packet_listing
from manip.conformance.suite.bridge import (
    Bridge,
    FailureLog,
    StopRun,
    connect_fresh,
    hypothesis_settings,
    run_in_worker,
)
from manip.conformance.suite.case import CaseFailure, case
from manip.conformance.suite.context import Answer, CaseContext, Probe
from manip.conformance.suite.invariants import TRANSCRIPT
from manip.conformance.suite.strategies import (
    bad_speed_factors,
    f_floats_between,
    float_requests,
    joints_out_of_range,
    joints_within,
    requests_of,
    reserved_float_data,
    speed_factors,
    step_from,
    unit_offsets,
    unknown_opcodes,
    wrong_length_data,
)
from manip.links import open_connection
from manip.spec import SPEC, RequestName, RequestOpcode
from manip.spec.constants import ASYNC_ERROR_OPS, ServerOp
from manip.spec.notation import octal

__all__ = ["STEPS_PER_EXAMPLE", "Step", "replay", "replay_async"]

STEPS_PER_EXAMPLE: Final = 20
MIN_WORKING_SPEED: Final = 0.05
"""The slowest speed factor the machine leaves in force while it may queue moves."""
MACHINE_BUDGET: Final = 50.0
END_QUIET: Final = 0.01
"""Seconds the end of each run waits for stray answers."""
ABORT_WAIT: Final = 0.05
"""Seconds the abort rule waits after killing power: a few servo cycles for the move process to notice."""


@dataclass(frozen=True)
class Step:
    """One step of a counterexample: a request sent (opcode, data) or a pause (``wait`` seconds)."""

    rule: str
    opcode: int = 0
    data: bytes = b""
    wait: float = 0.0
    packet_no: int | None = None
    """The Chaos packet number the request went out with (None: not sent)."""

    def show(self) -> str:
        if self.opcode == 0:
            return f"wait {self.wait:g} s"
        op = SPEC.requests.get(self.opcode)
        name = op.name if op else "unknown opcode"
        number = f"#{self.packet_no}" if self.packet_no is not None else "(not sent)"
        data = self.data.hex(" ") or "(none)"
        return f"{number:<6} 0{self.opcode:o} {name:<26} data {data}   [{self.rule}]"

    def as_python(self) -> str:
        return repr(self.wait) if self.opcode == 0 else f"(0o{self.opcode:o}, {self.data.hex()!r})"


@dataclass(eq=False)
class MachineFailure(Evidence):
    """A failed run of the machine, with the steps that led to it."""

    def __init__(self, *args: Any, steps: Iterable[Step] = (), **kwargs: Any) -> None:
        Evidence.__init__(self, *args, **kwargs)
        self.steps = list(steps)


@dataclass
class _Env:
    """What one case run gives its machines."""

    ctx: CaseContext
    bridge: Bridge
    arm: TargetArm
    motion: bool
    safe_ops: list[RequestOpcode]
    """Opcodes malformed requests may be built on."""
    log: FailureLog[MachineFailure]
    runs: dict[str, int]
    found: DistinctViolations[MachineFailure]
    """The model's disagreements with the server: each distinct one kept, and the run goes on."""


async def _exchange(probe: Probe, opcode: int, data: bytes) -> tuple[int, Answer, list[WirePacket]]:
    """Send one request and take its whole answer, with the unsolicited packets that came before it."""
    before = len(probe.unsolicited)
    number = await probe.request(opcode, data)
    op = SPEC.requests.get(opcode)
    if op is not None and op.response.form == "multi":
        answer = await probe.replies_until_empty(number)
    else:
        answer = await probe.reply(number)
    return number, answer, probe.unsolicited[before:]


async def _quiet(probe: Probe, seconds: float) -> list[WirePacket]:
    """Everything that arrives within ``seconds`` (stopping early if the connection ends)."""
    loop = asyncio.get_running_loop()
    end = loop.time() + seconds
    out: list[WirePacket] = []
    while (left := end - loop.time()) > 0:
        packet = await probe.next_packet(left)
        if packet is None:
            break
        out.append(packet)
    return out


class ArmProtocolMachine(RuleBasedStateMachine):
    """The machine; :func:`_machine_class` binds it to one case run (``env``)."""

    env: ClassVar[_Env]
    transforms = Bundle("transforms")

    def __init__(self) -> None:
        super().__init__()
        self.env.runs["examples"] += 1
        arm = self.env.arm
        self.model = ProtocolModel(limits=arm.limits, dof=arm.dof, served=arm.operations)
        self.steps: list[Step] = []
        self.probe: Probe | None = None
        self.position: Joints = self.env.arm.ready
        self.failed = False
        self.disagreed: list[MachineFailure] = []
        """This run's disagreements with the model, in order (the run went on after each)."""

    # ------------------------------------------------------------------------------- plumbing
    @property
    def bridge(self) -> Bridge:
        return self.env.bridge

    def _fail(
        self,
        clause: str,
        message: str,
        expected: str,
        actual: str,
        data: bytes = b"",
        packets: Sequence[WirePacket] = (),
        invariant: str | None = None,
    ) -> MachineFailure:
        self.failed = True
        run = list(self.probe.packets) if self.probe is not None else []
        failure = MachineFailure(
            clause,
            message,
            expected,
            actual,
            data,
            list(packets),
            run,
            invariant=invariant,
            steps=list(self.steps),
        )
        self.env.log.add(failure, len(self.steps))
        self.bridge.failure_seen()
        return failure

    def _disagreed(
        self,
        violation: Violation | None,
        packets: Sequence[WirePacket] = (),
        data: bytes = b"",
        what: str = "an asynchronous packet",
    ) -> None:
        """A disagreement with the model is kept (once per kind) and the run goes on: the caller's model
        then takes the state the server showed."""
        if violation is None:
            return
        assert violation.clause is not None  # the model's violations always name one
        run = list(self.probe.packets) if self.probe is not None else []
        found = MachineFailure(
            violation.clause,
            f"{what}: the arm model does not allow {violation.actual}",
            violation.expected,
            violation.actual,
            data,
            list(packets),
            run,
            steps=list(self.steps),
        )
        self.env.found.add(_kind(found), found)
        self.disagreed.append(found)

    def _checked(self, violations: Sequence[Any]) -> None:
        """Raise the first MUST violation a checker found."""
        found = must(violations)
        if found:
            first = found[0]
            assert first.clause is not None  # a checker's violations always name one
            packets = [first.packet] if first.packet is not None else []
            raise self._fail(
                first.clause,
                first.message,
                first.expected,
                first.actual,
                first.data,
                packets,
                invariant=TRANSCRIPT.name,
            )

    def _unsolicited(self, packets: Sequence[WirePacket]) -> None:
        """Judge packets that arrived while no answer was due (asynchronous ones, or stray answers)."""
        for packet in packets:
            self._checked(check_server_opcode(packet))
            if packet.is_close:
                raise self._fail(
                    "request.one-reply",
                    "the connection ended",
                    "the connection open",
                    describe(packet),
                    packet.data,
                    [packet],
                )
            if packet.opcode in ANSWER_OPCODES:
                raise self._fail(
                    "request.one-reply",
                    f"{describe(packet)} arrived while no request was outstanding",
                    "one answer per request, nothing more",
                    f"an extra {describe(packet)}",
                    packet.data,
                    [packet],
                )
            if packet.opcode == ServerOp.ASYNCHRONOUS_RESPONSE:
                self.env.ctx.exercised("async.layout", "async.only-when-requested", "async.codes")
                self._checked(check_async_packet(packet, None))
                message = decode_async(packet.data)
                self._disagreed(
                    self.model.on_async_response(
                        message.request_number, message.condition, message.word2, message.word3
                    ),
                    [packet],
                    packet.data,
                )
            elif packet.opcode in ASYNC_ERROR_OPS:
                self.env.ctx.exercised("async-error.request-number", "error.severity-matches-opcode")
                self._checked(check_error_packet(packet))
                if packet.opcode == ServerOp.ASYNCHRONOUS_ERROR:
                    error = error_of(packet)
                    if error is None:
                        raise self._fail(
                            "error-string.format",
                            "an asynchronous error string that does not decode",
                            "an error string",
                            packet.data.hex(),
                            packet.data,
                            [packet],
                            invariant=TRANSCRIPT.name,  # what check_error_packet finds
                        )
                    self._disagreed(
                        self.model.on_async_error(error.request_number, error.error), [packet], packet.data
                    )

    def send(self, rule: str, opcode: int, data: bytes = b"") -> Answer:
        """One request through the model: send, judge what came before the answer, judge the answer."""
        assert self.probe is not None
        self.steps.append(Step(rule, opcode, data))
        sent = len(self.probe.packets)
        try:
            number, answer, early = self.bridge.call(_exchange(self.probe, opcode, data))
        except CaseFailure as exc:
            self._sent_as(sent)
            raise self._fail(
                exc.clause or "request.one-reply",
                exc.message,
                exc.expected,
                exc.actual,
                exc.data,
                self.probe.packets[-3:],
                invariant=TRANSCRIPT.name,  # the probe's own failures (no answer, no connection)
            ) from None
        self._sent_as(sent)
        self.model.sent(number)
        self._unsolicited(early)
        expectation = self.model.expect(opcode, data)
        packets = [answer.request, *answer.packets]
        if expectation.discard:  # check_reply would judge the discarded request as if it were executed
            self._check_echo(answer, packets)
        else:
            self._checked(check_reply(answer.request, answer.packets))
        if answer.opcode == ServerOp.FATAL_ERROR:
            raise self._fail(
                "request.one-reply",
                "a fatal error",
                expectation.describe(),
                str(answer),
                answer.data,
                packets,
            )
        view = reply_view(answer)
        if not view.normal and view.error is None:
            raise self._fail(
                "error-string.format",
                "an error string that does not decode",
                "an error string",
                answer.data.hex(),
                answer.data,
                packets,
                invariant=TRANSCRIPT.name,  # what check_error_packet finds
            )
        op = SPEC.requests.get(opcode)
        what = f"request #{number} ({op.name if op else f'opcode {octal(opcode)}'})"
        self._disagreed(self.model.judge(expectation, view), packets, answer.data, what)
        self.env.ctx.exercised(*_judged_clauses(op, expectation, view))
        self.model.observe(number, opcode, data, view)
        return answer

    def _sent_as(self, since: int) -> None:
        """Give the last step the packet number its request went out with (the first request recorded
        on the probe from index ``since`` on)."""
        assert self.probe is not None
        for packet in self.probe.packets[since:]:
            if packet.direction == "c2s" and not packet.is_close:
                self.steps[-1] = replace(self.steps[-1], packet_no=packet.packet_no)
                return

    def _check_echo(self, answer: Answer, packets: Sequence[WirePacket]) -> None:
        if answer.number != answer.request.packet_no:
            raise self._fail(
                "response.echoes-request-number",
                "the answer carries the wrong request number",
                f"request number {answer.request.packet_no}",
                f"request number {answer.number}",
                answer.data,
                packets,
            )

    def call(self, rule: str, name: RequestName, **values: Any) -> Answer:
        return self.send(rule, SPEC.request(name).opcode, encode_request(name, **values))

    def pause(self, seconds: float) -> None:
        assert self.probe is not None
        self.steps.append(Step("wait", wait=seconds))
        self._unsolicited(self.bridge.call(_quiet(self.probe, seconds)))

    # ------------------------------------------------------------------------------- set-up
    @initialize(power=st.booleans())
    def connect(self, power: bool) -> None:
        self.probe = self.bridge.call(connect_fresh(self.env.ctx))
        initial = self.probe.rfc_packet_no
        if initial is None and self.probe.initial is not None:
            initial = word(self.probe.initial.data)
        if initial is not None:
            self.model.sent(initial, initial=True)
        if self.env.motion:
            self.call("initialize", "enable-power" if power else "kill-power")
        self.read_joints()

    def teardown(self) -> None:
        probe = self.probe
        if probe is None:
            return
        try:
            if not self.failed:
                self.pause(END_QUIET)
                self._checked(check_transcript(probe.packets, rfc_packet_no=probe.rfc_packet_no))
            if not self.failed and self.disagreed:
                # The run went on after its disagreements; at its end the first fails it, so that
                # Hypothesis shrinks a run that shows one (the others are reported unshrunk).
                first = self.disagreed[0]
                self.failed = True
                self.env.log.add(first, len(first.steps))
                self.bridge.failure_seen()
                raise first
        finally:
            self.bridge.call(probe.close())  # the next run needs the robot: one client at a time

    # ------------------------------------------------------------------------------- reading
    @rule()
    def here(self) -> None:
        self.call("here", "here")

    @rule()
    def read_joints(self) -> None:
        answer = self.call("joint-angles", "joint-angles")
        if answer.is_response and len(answer.data) > 2:
            try:
                q = floats(answer)
            except CodecError:
                return
            lim = self.env.arm.limits
            self.position = (
                min(max(q[0], lim.lower[0]), lim.upper[0]),
                min(max(q[1], lim.lower[1]), lim.upper[1]),
                min(max(q[2], lim.lower[2]), lim.upper[2]),
                min(max(q[3], lim.lower[3]), lim.upper[3]),
                min(max(q[4], lim.lower[4]), lim.upper[4]),
                min(max(q[5], lim.lower[5]), lim.upper[5]),
            )

    @rule(target=transforms, data=st.data())
    def solve_backwards(self, data: st.DataObject) -> tuple[float, ...]:
        """Solve backwards; the transform joins the bundle moves draw from (the server's own when it
        answers, so the model may insist the move is reachable; else the PUMA 600's, so the bundle
        fills the same way whatever the target answers and Hypothesis replays stay consistent)."""
        q = data.draw(joints_within(self.env.arm.limits, margin=1.0), label="joints")
        answer = self.call("solve-backwards", "solve-backwards", joints=list(q))
        if answer.is_response:
            try:
                t = floats(answer)
            except CodecError:
                pass
            else:
                self.model.reachable.add(t)
                return t
        return forward(q).to_floats()

    @rule()
    def describe_self(self) -> None:
        self.call("describe-self", "describe-self")

    # ------------------------------------------------------------------------------- config
    @rule(factor=st.one_of(st.just(1.0), f_floats_between(MIN_WORKING_SPEED, 1.0)))
    def set_speed(self, factor: float) -> None:
        self.call("set-speed", "set-speed", factor=factor)

    @rule(factor=speed_factors)
    def set_speed_extreme(self, factor: float) -> None:
        """Any factor the spec allows, down to the smallest F float; then back to full speed, because a
        move queued at 1e-38 of full speed would take longer than the run (and a server that plans the
        whole path of a straight-line move when it is queued may take as long to plan it)."""
        self.call("set-speed-extreme", "set-speed", factor=factor)
        self.call("set-speed-extreme: restore", "set-speed", factor=1.0)

    @rule(factor=bad_speed_factors)
    def set_speed_out_of_range(self, factor: float) -> None:
        self.call("set-speed-out-of-range", "set-speed", factor=factor)

    @rule(mask=st.integers(0, 3))
    def request_notifications(self, mask: int) -> None:
        self.call("request-notifications", "request-notifications", mask=mask)

    @rule(value=st.one_of(st.integers(0, 1), st.integers(2, 255)))
    def set_configuration(self, value: int) -> None:
        self.call("set-configuration", "set-configuration", configuration=value)

    # ------------------------------------------------------------------------------- power
    @precondition(lambda self: self.env.motion)
    @rule()
    def enable_power(self) -> None:
        self.call("enable-power", "enable-power")

    @precondition(lambda self: self.env.motion)
    @rule()
    def kill_power(self) -> None:
        self.call("kill-power", "kill-power")

    @precondition(lambda self: self.env.motion)
    @rule()
    def reset_abort(self) -> None:
        self.call("reset-abort", "reset-abort")

    # ------------------------------------------------------------------------------- motion
    @precondition(lambda self: self.env.motion)
    @rule(offsets=unit_offsets)
    def set_joint_angles(self, offsets: tuple[float, ...]) -> None:
        goal = step_from(self.position, offsets, self.env.arm.limits, step=5.0)
        self.call("set-joint-angles", "set-joint-angles", joints=list(goal))

    @precondition(lambda self: self.env.motion)
    @rule(data=st.data())
    def set_joint_angles_out_of_range(self, data: st.DataObject) -> None:
        goal, _ = data.draw(joints_out_of_range(self.env.arm.limits), label="goal")
        self.call("set-joint-angles-out-of-range", "set-joint-angles", joints=list(goal))

    @precondition(lambda self: self.env.motion)
    @rule(t=transforms)
    def move(self, t: tuple[float, ...]) -> None:
        self.call("move", "move", transform=list(t))

    @precondition(lambda self: self.env.motion)
    @rule(t=transforms)
    def straight_move(self, t: tuple[float, ...]) -> None:
        self.call("straight-move", "straight-move", transform=list(t))

    @precondition(lambda self: self.env.motion)
    @rule(
        straight=st.booleans(),
        delta=st.tuples(*[f_floats_between(-5.0, 5.0)] * 3, *[f_floats_between(-2.0, 2.0)] * 3),
    )
    def incremental_move(self, straight: bool, delta: tuple[float, ...]) -> None:
        name: RequestName = "incremental-straight-move" if straight else "incremental-move"
        per_unit = self.env.ctx.options.mm_per_unit  # dX dY dZ drawn in mm, sent in --length-unit
        self.call(name, name, delta=[*(d / per_unit for d in delta[:3]), *delta[3:]])

    @precondition(lambda self: self.env.motion)
    @rule()
    def ready(self) -> None:
        self.call("ready", "ready")

    @precondition(lambda self: self.env.motion)
    @rule(amount=st.integers(0, 0xFFFF))
    def hand(self, amount: int) -> None:
        self.call("hand", "hand", amount=amount)

    @precondition(lambda self: self.env.motion)
    @rule(joint=st.one_of(st.integers(1, 6), st.sampled_from([0, 7, 8, 0o100, 0xFF])))
    def free_joint(self, joint: int) -> None:
        """Free a joint; the next request (whatever rule sends it) must be discarded with done."""
        self.call("free-joint", "free-joint", joint=joint)

    @precondition(lambda self: self.env.motion)
    @rule(data=st.data())
    def abort_by_power_loss(self, data: st.DataObject) -> None:
        """Start a long move and kill power while it runs: the move process must abort (an
        asynchronous error), and motion is refused with AWA until a reset."""
        if self.model.powered is not True or self.model.aborted is not False:
            self.call("abort: enable-power", "enable-power")
        lim = self.env.arm.limits
        goal = list(self.position)
        joint = data.draw(st.integers(0, 5), label="joint")
        room_up, room_down = lim.upper[joint] - 1.0 - goal[joint], goal[joint] - lim.lower[joint] - 1.0
        goal[joint] += 20.0 if room_up >= room_down else -20.0
        self.call("abort: long move", "set-joint-angles", joints=goal)
        self.call("abort: kill-power", "kill-power")
        self.pause(ABORT_WAIT)

    @rule(seconds=st.sampled_from([0.005, 0.02, 0.06]))
    def wait(self, seconds: float) -> None:
        self.pause(seconds)

    # ------------------------------------------------------------------------------- malformed
    @rule(opcode=unknown_opcodes(), data=st.binary(max_size=24))
    def unknown_opcode(self, opcode: int, data: bytes) -> None:
        self.send("unknown-opcode", opcode, data)

    @rule(data=st.data())
    def wrong_length(self, data: st.DataObject) -> None:
        op = data.draw(st.sampled_from(self.env.safe_ops), label="opcode")
        self.send("wrong-length", op.opcode, data.draw(wrong_length_data(op), label="data"))

    @rule(data=st.data())
    def reserved_float(self, data: st.DataObject) -> None:
        ops = [op for op in float_requests() if op in self.env.safe_ops]
        op = data.draw(st.sampled_from(ops), label="opcode")
        body, _ = data.draw(reserved_float_data(op), label="data")
        self.send("reserved-float", op.opcode, body)


def _judged_clauses(
    op: RequestOpcode | None, expectation: Expectation, view: AnswerSummary
) -> tuple[str, ...]:
    """The clauses one judged answer exercised: one reply echoing its request, the clause a reply outside
    the allowed ones breaks, and, for a normal reply, its opcode's reply clauses (an error: that it is
    the reply)."""
    clauses = ["request.one-reply", "response.echoes-request-number", expectation.clause]
    if op is None:
        clauses.append("request.unknown-opcode")
    elif view.normal:
        clauses += op.reply_clauses
    else:
        clauses.append("error.non-fatal-is-reply")
    return tuple(clauses)


def _machine_class(env: _Env) -> type[ArmProtocolMachine]:
    return type("ArmProtocolMachine", (ArmProtocolMachine,), {"env": env})


# ------------------------------------------------------------------------------------- the case
def _counterexample(
    failure: MachineFailure, address: str, reproduce: str | None = None, *, shrunk: bool = True
) -> str:
    """The counterexample for the report: its requests, how to see it again, the failing run's packets.
    ``reproduce``: the case's command, for a target that will be gone (the embedded server), in place
    of the line that replays the requests against ``address``.  ``shrunk``: Hypothesis shrank it (a
    disagreement the run went on after was not shrunk: its steps are the run's up to it)."""
    which = "the shrunk counterexample" if shrunk else "the run up to it (not shrunk)"
    lines = [
        failure.actual,
        "",
        f"requests of {which} ({len(failure.steps)} steps, on a fresh connection; the last one failed):",
    ]
    lines += [f"  {i:>3}. {step.show()}" for i, step in enumerate(failure.steps, 1)]
    shown = ", ".join(step.as_python() for step in failure.steps)
    if reproduce:
        lines += ["reproduce with (the same seed draws the same counterexample):", f"  {reproduce}"]
    else:
        lines += [
            "replay with:",
            '  python -c "from manip.conformance.cases.server.stateful import replay; '
            f'replay({address!r}, [{shown}])"',
        ]
    if failure.example:
        lines.append("packets of the failing run (> the ones that show the failure):")
        lines += packet_listing(failure.example, marked=failure.packets, from_open=True)
    elif failure.packets:
        lines.append("packets:")
        lines += packet_listing(failure.packets)
    return "\n".join(lines)


@case(
    "stateful.arm-model",
    # the model's violations (it names no other clause), and what the machine checks itself
    clauses=sorted(
        MODEL_CLAUSES
        | {
            "request.one-reply",
            "response.echoes-request-number",
            "error.non-fatal-is-reply",
            "motion.no-power",
            "motion.abort",
            "motion.reset",
            "motion.checked-before-queue",
            "motion.reply-before-motion",
            "speed.range",
            "async.only-when-requested",
            "async.layout",
            "async-error.request-number",
            "free-joint.data",
            "free-joint.awaits-next-packet",
            "free-joint.replies",
            "kill-power.done",
            "enable-power.done",
            "set-configuration.data",
            "hand.data",
            "request.unknown-opcode",
            "request.data-length",
            "request.reserved-float",
        }
    ),
    technique="stateful",
    hazard="config",
    deadline=90.0,
    extensions=["request-notifications", "reset-abort"],
)
async def arm_model(ctx: CaseContext) -> None:
    """Random request sequences against a model of the arm's protocol state (power, abort, segments,
    speed, notifications, free joint): exactly the replies the model allows, one per request."""
    probe = await ctx.connect()
    arm = await describe_target(ctx, probe)
    await probe.close()
    motion = "motion" in ctx.options.allowed_hazards and "power" in ctx.options.allowed_hazards
    safe = requests_of(ctx.options.allowed_hazards if motion else {"read-only", "config"})
    safe = [op for op in safe if op.request.fixed_size is not None]
    log: FailureLog[MachineFailure] = FailureLog()
    runs = {"examples": 0}
    disagreements: DistinctViolations[MachineFailure] = DistinctViolations()

    def work(bridge: Bridge) -> tuple[MachineFailure | None, str]:
        env = _Env(ctx, bridge, arm, motion, safe, log, runs, disagreements)
        machine = _machine_class(env)
        settings = hypothesis_settings(ctx.max_examples, stateful_step_count=STEPS_PER_EXAMPLE)
        try:
            run_state_machine_as_test(seed(ctx.seed)(machine), settings=settings)
        except MachineFailure as exc:
            return exc, ""
        except Flaky as exc:
            found = [e for e in getattr(exc, "exceptions", ()) if isinstance(e, MachineFailure)]
            if found or log.best is not None:
                return (found[0] if found else log.best), (
                    "the failure did not reproduce on every replay (a timing-dependent target?); "
                    f"{type(exc).__name__}"
                )
            ctx.note(f"Hypothesis: {type(exc).__name__}, but no failure was seen")
        except StopRun:
            if log.best is not None:
                return log.best, f"shrinking stopped after its time budget ({log.count} failing runs seen)"
            if bridge.stopped_by_budget:
                ctx.note(
                    f"stopped after its {MACHINE_BUDGET:g} s budget, {runs['examples']} runs, no failure"
                )
        return None, ""

    failure, note = await run_in_worker(work, budget=MACHINE_BUDGET)
    ctx.note(
        f"{runs['examples']} runs of up to {STEPS_PER_EXAMPLE} steps (seed {ctx.seed}); "
        f"motion and power rules {'on' if motion else 'off'}"
    )
    if note:
        ctx.note(note)
    reproduce = ctx.reproduce if ctx.options.embedded and ctx.reproduce else None
    address = ctx.options.address or "tcp://HOST:PORT"
    others = _record_disagreements(ctx, disagreements, address, reproduce, failure)
    if failure is None and others:
        ctx.show_packets([*ctx.transcript, *others])
    if failure is not None:
        shown = _counterexample(failure, address, reproduce)
        ctx.show_packets([*(failure.example or failure.packets), *others])
        culprit = failure.culprit
        ctx.fail_with(replace(failure.violation, actual=shown, packet=culprit))


def _kind(failure: MachineFailure) -> tuple[str, ...]:
    """What makes two disagreements the same: the clause, and the rule of the step it was found on."""
    rule = failure.steps[-1].rule if failure.steps else ""
    return (failure.violation.clause or "", rule)


def _record_disagreements(
    ctx: CaseContext,
    found: DistinctViolations[MachineFailure],
    address: str,
    reproduce: str | None,
    stopped: MachineFailure | None,
) -> list[WirePacket]:
    """Report every distinct disagreement with the model the runs went on after, but the one the case
    stops with (``stopped``, shrunk; its packets are the case's packet log); the packets that show them,
    which the packet log shows after that run's."""
    shown: list[WirePacket] = []
    for item in found.kept.values():
        if stopped is not None and _kind(item) == _kind(stopped):
            continue  # the one the case stops with, shrunk
        text = _counterexample(item, address, reproduce, shrunk=False)
        ctx.record(replace(item.violation, actual=text, packet=item.culprit))
        named = ctx.recorded[-1].packets  # the culprit, or what the context named for it
        shown += [p for p in (*item.packets, *named) if not any(p is q for q in shown)]
    if found.dropped:
        ctx.note(
            f"{found.dropped} more distinct disagreement(s) with the model not reported "
            f"(at most {found.bound} per case)"
        )
    return shown


# ------------------------------------------------------------------------------------- replay
Replayable = tuple[int, str] | float


async def replay_async(address: str, steps: Sequence[Replayable], *, timeout: float = 2.0) -> list[str]:
    """Send a counterexample's requests on a fresh connection, one at a time (a float is a pause in
    seconds), and return a line per packet received, for a human to compare with the failure."""
    lines: list[str] = []
    conn = await open_connection(address)
    try:

        async def take(seconds: float) -> None:
            loop = asyncio.get_running_loop()
            end = loop.time() + seconds
            while (left := end - loop.time()) > 0:
                try:
                    async with asyncio.timeout(left):
                        packet = await conn.receive()
                except TimeoutError:
                    return
                lines.append(f"  <- 0{packet.opcode:o} {packet.data.hex(' ')}")

        await take(0.1)
        for step in steps:
            if isinstance(step, float | int) and not isinstance(step, tuple):
                await take(float(step))
                continue
            opcode, data = step
            number = await conn.send(bytes.fromhex(data), opcode)
            lines.append(f"-> #{number} 0{opcode:o} {data}")
            await take(0.05)
        await take(timeout)
    finally:
        await conn.close()
    return lines


def replay(address: str, steps: Sequence[Replayable]) -> None:
    """Blocking :func:`replay_async` that prints what came back."""
    for line in asyncio.run(replay_async(address, steps)):
        print(line)
