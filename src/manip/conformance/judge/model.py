"""A pure model of what one connection of the arm protocol may answer, for the stateful cases.

Theory of operation
===================

The model holds what a client can know about the server from what it sent and what came back, and
for each request says which replies the spec allows (:class:`Expectation`); then it takes the reply
that actually came and updates itself (:meth:`ProtocolModel.observe`), and it judges every
asynchronous packet as it arrives (:meth:`ProtocolModel.on_async_response`,
:meth:`ProtocolModel.on_async_error`).  No I/O, no clock: packets and request numbers in, verdicts out.

State (``None`` = unknown to the client, e.g. a real arm's power when the connection opens)::

    powered        arm power                   enable-power -> True, kill-power -> False
    aborted        motion aborted (AWA)        an asynchronous error while segments may run -> True;
                                               enable-power / reset-abort (0260) -> False;
                                               kill-power while segments may run -> unknown
    outstanding    segments accepted and not known to be finished, in queue order
    next_segment   the number the next segment should get (SHOULD clause: +1 mod 2^16)
    notifications  the 0257 mask, and which mask was in force after each request (by number)
    free_wait      free joint was answered: the next packet is discarded with an empty done

How a request is judged (:meth:`ProtocolModel.expect`), from its bytes alone:

1. while ``free_wait``: only an empty done echoing its number (``free-joint.replies``);
2. an opcode the spec does not define: a command error (C), never a normal reply;
3. data that do not decode by the layout: wrong length or a reserved-operand float, a command error;
4. values outside what the spec allows (speed factor, free-joint joint number): C; configuration bits
   besides bit 0: done (the 1985 guide's answer) or C (erratum ``set-configuration``);
5. manip's extension opcodes (0240 and up) the server does not list under :operations may also be
   refused with a command error (an unserved opcode);
6. motion requests go through the gate: aborted -> AWA only (erratum ``abort-before-power``: the abort
   condition is reported before missing power); power off -> NAP; joint angles past a limit -> JOR; a
   transform (or increment) the model cannot vouch for -> TOR also allowed, never JOR (erratum
   ``transform-refusals``: JOR is for joint angles, TOR for every transform no in-range angles reach);
   when a state is unknown, both outcomes are allowed and the reply that comes settles it
   (:meth:`observe`);
7. otherwise the normal reply of the opcode's shape.

The model never allows a fatal error or a BE (bug) error.  While segments are outstanding it allows a
non-fatal error of any code to a motion request or free joint (queue full, joint busy: the 1985 guide
names no code for either; manip's server says SQF).  Segment numbers that do not increase by one are
recorded in :attr:`ProtocolModel.segment_violations` rather than refused, because that clause is a SHOULD.

A run goes on after the server disagrees with the model: :meth:`ProtocolModel.observe` takes the reply
that came into the state (a NAP where power was expected means the arm is unpowered, an AWA that it is
aborted), and :class:`DistinctViolations` keeps each distinct disagreement once, up to a bound.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Final, Generic, TypeVar

from manip.arm.kinematics import PUMA600, JointLimits
from manip.codecs.error_string import ErrorMessage
from manip.codecs.errors import CodecError, DecodeError
from manip.codecs.messages import Value, decode_request
from manip.conformance.judge.violation import Violation
from manip.spec import SPEC, RequestOpcode
from manip.spec.constants import AsyncCondition

__all__ = [
    "MAX_DISTINCT_VIOLATIONS",
    "MODEL_CLAUSES",
    "AnswerSummary",
    "DistinctViolations",
    "Expectation",
    "ProtocolModel",
    "violation",
]

MODEL_CLAUSES: Final = frozenset(
    {
        "async-error.request-number",
        "async.codes",
        "async.layout",
        "async.only-when-requested",
        "calibrate.done",
        "enable-power.done",
        "error.severity-matches-opcode",
        "free-joint.data",
        "free-joint.replies",
        "hand.data",
        "here.transform",
        "kill-power.done",
        "motion.abort",
        "motion.checked-before-queue",
        "motion.no-power",
        "motion.reset",
        "request.data-length",
        "request.one-reply",
        "request.reserved-float",
        "request.unknown-opcode",
        "response.data-layout",
        "response.done-empty",
        "response.segment-number",
        "segment.number-increases",
        "set-configuration.data",
        "solve-forwards.errors",
        "speed.range",
    }
)
"""Every clause a :func:`violation` of the model may name (checked when one is made): the stateful case,
which reports the model's violations, declares them all."""

WORD: Final = 0xFFFF
#: A transform whose rotation deviates less than this from orthonormal is certainly valid; more than
#: :data:`NOT_ROTATION` is certainly not (the model allows either answer in between).
ROTATION_OK: Final = 1e-5
NOT_ROTATION: Final = 1e-2
#: Joints this far (deg) inside/outside a limit are certainly in/out of range for the model.
LIMIT_SLACK: Final = 1e-3
MOTION_NAMES: Final = frozenset(op.name for op in SPEC.requests.values() if op.response.form == "segment")
Kept = TypeVar("Kept")
_SEGMENT_BIT: Final = 1 << SPEC.async_codes[AsyncCondition.SEGMENT_COMPLETED].notification_bit
_GUARD_BIT: Final = 1 << SPEC.async_codes[AsyncCondition.GUARD_HIT].notification_bit
_RESETS: Final = frozenset({"enable-power", "reset-abort"})
"""The requests that reset an abort (erratum abort-reset): never refused for it."""
_DEFINED_MASK: Final = sum(1 << code.notification_bit for code in SPEC.async_codes.values())


@dataclass(frozen=True)
class Expectation:
    """The replies the spec allows to one request in the model's state."""

    normal: bool
    """A normal RESPONSE of the opcode's shape is allowed."""
    codes: frozenset[str] = frozenset()
    """Error codes allowed in a non-fatal error (any non-bug, non-fatal severity)."""
    command: bool = False
    """A command error (severity C, any code) is allowed."""
    discard: bool = False
    """Only an empty done is allowed: the packet after free joint."""
    any_code: bool = False
    """A non-fatal error with any code is allowed: the condition is one the 1985 guide names no code for
    (E.2: "others may be used by specific manipulators"; erratum ``unnamed-error-codes``)."""
    excluded: frozenset[str] = frozenset()
    """Codes ``any_code`` still does not allow (JOR for a transform: erratum ``transform-refusals``)."""
    clause: str = "request.one-reply"
    """The clause a reply outside the allowed ones breaks."""
    why: str = ""

    def describe(self) -> str:
        """The allowed replies, for a failure message."""
        if self.discard:
            return "an empty done (the packet after free joint is discarded)"
        parts = ["the normal reply"] if self.normal else []
        if self.command:
            parts.append("a command error (severity C)")
        parts += [f"a non-fatal error {code}" for code in sorted(self.codes)]
        if self.any_code:
            but = f" but {', '.join(sorted(self.excluded))}" if self.excluded else ""
            parts.append(f"a non-fatal error with any code{but}")
        text = " or ".join(parts) if parts else "nothing"
        return f"{text} ({self.why})" if self.why else text


@dataclass(frozen=True)
class AnswerSummary:
    """What came back for one request, as the model needs it."""

    normal: bool
    """A RESPONSE (0200) rather than an error."""
    empty: bool = False
    """A RESPONSE carrying only the request number."""
    segment: int | None = None
    """The segment number of a motion reply."""
    error: ErrorMessage | None = None
    """The error string of a non-fatal error."""


MAX_DISTINCT_VIOLATIONS: Final = 20
"""How many distinct disagreements with the model one stateful run reports (the rest are counted)."""


@dataclass
class DistinctViolations(Generic[Kept]):
    """The distinct disagreements a run found, the first of each kind kept (a kind: the clause and the
    request it was found on, as the caller names them), up to ``bound``.  The run goes on after each:
    the model takes the state the server showed (:meth:`ProtocolModel.observe` takes the reply that
    came, not the one expected), so one disputed answer does not hide what follows it."""

    bound: int = MAX_DISTINCT_VIOLATIONS
    kept: dict[tuple[str, ...], Kept] = field(default_factory=dict)
    dropped: int = 0
    """Distinct violations past the bound, counted only."""

    def add(self, key: tuple[str, ...], item: Kept) -> bool:
        """Keep ``item`` if ``key`` is a new kind and the bound allows; True if kept."""
        if key in self.kept:
            return False
        if len(self.kept) >= self.bound:
            self.dropped += 1
            return False
        self.kept[key] = item
        return True

    def __len__(self) -> int:
        return len(self.kept)


def violation(clause: str, expected: str, actual: str) -> Violation:
    """A rule the server broke, found by the model: a clause of :data:`MODEL_CLAUSES` (checked)."""
    if clause not in MODEL_CLAUSES:
        raise ValueError(f"model violation of clause {clause!r}, which is not in MODEL_CLAUSES")
    return Violation(f"the arm model does not allow {actual}", clause, expected=expected, actual=actual)


@dataclass
class ProtocolModel:
    """One connection's protocol state as the client can know it; see the module docstring."""

    limits: JointLimits = PUMA600.limits
    dof: int = 6
    powered: bool | None = None
    aborted: bool | None = None
    free_wait: bool = False
    notifications: int = 0
    speed: float | None = None
    outstanding: list[int] = field(default_factory=list)
    next_segment: int | None = None
    segment_violations: list[Violation] = field(default_factory=list)
    served: frozenset[int] | None = None
    """The opcodes describe self lists under :operations (None: unknown); extensions outside it may be
    refused as unserved."""
    reachable: set[tuple[float, ...]] = field(default_factory=set)
    """Transforms (12 floats) the server itself produced from in-range joint angles."""
    _mask_after: dict[int, int] = field(default_factory=dict)
    _order: dict[int, int] = field(default_factory=dict)
    _answered: int = -1
    """Index (in sending order) of the last request whose reply has come."""

    # ------------------------------------------------------------------------------- requests
    def sent(self, number: int, initial: bool = False) -> None:
        """A request with packet number ``number`` went out (``initial``: the RFC, before any)."""
        self._order[number & WORD] = len(self._order)
        if initial:
            self._mask_after[number & WORD] = self.notifications
            self._answered = self._order[number & WORD]

    def expect(self, opcode: int, data: bytes) -> Expectation:
        """What the spec allows as the reply to this request now."""
        if self.free_wait:
            return Expectation(False, discard=True, clause="free-joint.replies", why="free joint waits")
        op = SPEC.requests.get(opcode)
        if op is None:
            return Expectation(False, command=True, clause="request.unknown-opcode", why="unknown opcode")
        try:
            values = decode_request(opcode, data).values
        except DecodeError as exc:
            clause = (
                "request.reserved-float" if exc.clause == "float.reserved-operand" else "request.data-length"
            )
            return Expectation(False, command=True, clause=clause, why=exc.message)
        except CodecError as exc:
            return Expectation(False, command=True, clause="request.data-length", why=exc.message)
        expectation = self._expect_valid(op, values)
        if self.aborted is not False and op.name not in MOTION_NAMES and op.name not in _RESETS:
            # E.2: "no further commands will be processed until a reset": the others may get AWA too
            # (erratum awa-scope; server.motion.awa-reset-abort warns of it under a SHOULD clause)
            expectation = replace(expectation, codes=expectation.codes | {"AWA"})
        if op.extension and (self.served is None or opcode not in self.served):
            # manip's Puma extensions are optional: a server that does not list one may refuse it (C),
            # whatever the arm's state (an opcode it does not serve is not refused for power or abort)
            why = "; ".join(w for w in (expectation.why, "an extension the server does not list") if w)
            expectation = replace(expectation, command=True, why=why)
        return expectation

    def _expect_valid(self, op: RequestOpcode, values: Mapping[str, Value]) -> Expectation:
        name = op.name
        if name == "set-speed":
            factor = values["factor"]
            assert isinstance(factor, float)
            if 0.0 < factor <= 1.0:
                return Expectation(True, clause="speed.range", why=f"factor {factor!r} is in 0 < n <= 1")
            return Expectation(
                False, command=True, clause="speed.range", why=f"factor {factor!r} out of range"
            )
        if name == "request-notifications":
            mask = values["mask"]
            assert isinstance(mask, int)
            if mask & ~_DEFINED_MASK:  # bits the spec does not define: refusing or ignoring both pass
                return Expectation(True, command=True, why="mask has undefined bits")
            return Expectation(True, clause="response.done-empty")
        if name == "set-configuration":
            low = _int(values["configuration"]) & 0xFF  # erratum set-configuration: the low byte
            if low & 0xFE:  # the 1985 guide answers done; refusing bits it does not define is allowed too
                return Expectation(
                    True, command=True, clause="set-configuration.data", why="bits besides bit 0"
                )
            return Expectation(True, clause="set-configuration.data")
        if name == "free-joint":
            joint = _int(values["joint"]) & 0xFF  # the first data byte is the joint
            if not 1 <= joint <= self.dof:
                return Expectation(False, command=True, clause="free-joint.data", why=f"joint {joint}")
            return self._gate(optional=True, clause="free-joint.replies")
        if name == "hand":
            return self._gate(optional=True, clause="hand.data")
        if name in ("kill-power", "enable-power", "reset-abort"):
            return Expectation(True, clause=f"{name}.done" if name != "reset-abort" else "motion.reset")
        if name in MOTION_NAMES:
            return self._expect_motion(op, values)
        if name == "solve-forwards":
            return self._expect_transform(values, "solve-forwards.errors", vouch=False)
        if name in ("calibrate",):
            return Expectation(True, codes=frozenset({"NAP", "AWA"}), clause="calibrate.done")
        if op.extension:
            # the wrist extensions (the others are handled above): a Puma without Cougar refuses them (C)
            return Expectation(True, command=True, codes=frozenset({"NAP", "AWA"}), why="wrist opcode")
        return Expectation(True, clause="response.data-layout")

    def _gate(self, *, optional: bool = False, clause: str = "motion.no-power") -> Expectation:
        """The state refusals of a request that needs the arm (``optional``: may work without power)."""
        if self.aborted is True:
            if optional:
                return Expectation(True, codes=frozenset({"AWA"}), clause=clause, why="motion aborted")
            return Expectation(False, codes=frozenset({"AWA"}), clause="motion.abort", why="motion aborted")
        codes: set[str] = set()
        normal = True
        why = []
        if self.aborted is None:
            codes.add("AWA")
            why.append("abort state unknown")
        if self.powered is False:
            codes.add("NAP")
            normal = optional
            why.append("arm power off")
        elif self.powered is None:
            codes.add("NAP")
            why.append("arm power unknown")
        if self.outstanding:
            # queue full, or no freeing a joint while the arm moves: the 1985 guide names no code for
            # either, so any non-fatal error may say it (E.2: "others may be used"); manip's is SQF
            why.append("segments may be running")
            return Expectation(
                normal, codes=frozenset(codes), any_code=True, clause=clause, why="; ".join(why)
            )
        return Expectation(normal, codes=frozenset(codes), clause=clause, why="; ".join(why))

    def _expect_motion(self, op: RequestOpcode, values: Mapping[str, Value]) -> Expectation:
        gate = self._gate(clause="motion.no-power")
        if op.name in ("set-joint-angles", "compliant-move"):
            joints = values["joints"]
            assert isinstance(joints, tuple)
            out = [j for j, q in enumerate(joints, 1) if not self._inside(j, float(q), -LIMIT_SLACK)]
            sure_in = all(self._inside(j, float(q), LIMIT_SLACK) for j, q in enumerate(joints, 1))
            if out:
                data = Expectation(
                    False,
                    codes=frozenset({"JOR"}),
                    clause="motion.checked-before-queue",
                    why=f"joint(s) {out} out of range",
                )
            elif sure_in:
                data = Expectation(True, clause="response.segment-number", why="joints in range")
            else:
                data = Expectation(True, codes=frozenset({"JOR"}), why="joints at a limit")
        elif op.name in ("move", "straight-move"):
            data = self._expect_transform(values, "motion.checked-before-queue", vouch=op.name == "move")
        elif op.name == "ready":
            data = Expectation(True, clause="response.segment-number")
        else:  # incremental moves: the model does not know where they lead, but they lead to a transform
            data = Expectation(True, codes=frozenset({"TOR"}), clause="response.segment-number")
        return _combine(gate, data)

    def _expect_transform(self, values: Mapping[str, Value], clause: str, *, vouch: bool) -> Expectation:
        floats = values["transform"]
        assert isinstance(floats, tuple)
        deviation = _rotation_deviation(floats)
        if deviation > NOT_ROTATION:
            return Expectation(False, command=True, clause="here.transform", why="N, O, A are not a rotation")
        command = deviation > ROTATION_OK
        if vouch and tuple(floats) in self.reachable:
            return Expectation(True, command=command, clause=clause, why="the server's own transform")
        # TOR, or for a transform no joint angles reach any code but JOR (erratum unnamed-error-codes)
        return Expectation(
            True,
            codes=frozenset({"TOR"}),
            any_code=True,
            excluded=frozenset({"JOR"}),
            command=command,
            clause=clause,
            why="perhaps out of reach",
        )

    def _inside(self, joint: int, q: float, slack: float) -> bool:
        """``q`` is within joint ``joint``'s range shrunk by ``slack`` (grown when negative)."""
        if joint > len(self.limits.lower):
            return True
        return self.limits.lower[joint - 1] + slack <= q <= self.limits.upper[joint - 1] - slack

    # -------------------------------------------------------------------------------- replies
    def judge(self, expectation: Expectation, reply: AnswerSummary) -> Violation | None:
        """Whether ``reply`` is one ``expectation`` allows."""
        if expectation.discard:
            if reply.normal and reply.empty:
                return None
            return violation(expectation.clause, expectation.describe(), _show(reply))
        if reply.normal:
            if expectation.normal:
                return None
            return violation(expectation.clause, expectation.describe(), _show(reply))
        err = reply.error
        assert err is not None
        if err.severity in ("F", "BF", "BE"):
            return violation(
                "error.severity-matches-opcode" if err.severity != "BE" else expectation.clause,
                expectation.describe(),
                _show(reply),
            )
        if err.code in expectation.codes or (expectation.command and err.severity == "C"):
            return None
        if expectation.any_code and err.code not in expectation.excluded:
            return None
        return violation(expectation.clause, expectation.describe(), _show(reply))

    def observe(self, number: int, opcode: int, data: bytes, reply: AnswerSummary) -> None:
        """Take the (already judged) reply to request ``number`` into the state."""
        index = self._order.get(number & WORD)
        if index is not None:
            self._answered = max(self._answered, index)
        try:
            if self.free_wait:
                self.free_wait = False
                return
            op = SPEC.requests.get(opcode)
            if op is None:
                return
            if not reply.normal:
                self._observe_refusal(reply)
                return
            try:
                values = decode_request(opcode, data).values
            except CodecError:
                return  # a server that answered malformed data normally; the judge has said so
            self._observe_normal(op, values, reply)
        finally:
            self._mask_after[number & WORD] = self.notifications

    def _observe_refusal(self, reply: AnswerSummary) -> None:
        assert reply.error is not None
        code = reply.error.code
        if code == "AWA":
            self.aborted = True
        elif code == "NAP":
            self.powered = False
            if self.aborted is None:
                self.aborted = False  # AWA would have come first (erratum abort-before-power)

    def _observe_normal(self, op: RequestOpcode, values: Mapping[str, Value], reply: AnswerSummary) -> None:
        name = op.name
        if name == "enable-power":
            self.powered, self.aborted = True, False
        elif name == "kill-power":
            self.powered = False
            if self.outstanding and self.aborted is False:
                self.aborted = None  # the move process will abort what is still running
        elif name == "reset-abort":
            self.aborted = False
        elif name == "request-notifications":
            mask = values["mask"]
            assert isinstance(mask, int)
            self.notifications = mask & _DEFINED_MASK
        elif name == "set-speed":
            factor = values["factor"]
            assert isinstance(factor, float)
            self.speed = factor
        elif name == "free-joint":
            self.free_wait = True
        elif name in MOTION_NAMES:
            self.powered = True if self.powered is None else self.powered
            self.aborted = False if self.aborted is None else self.aborted
            if reply.segment is not None:
                self._take_segment(reply.segment)

    def _take_segment(self, segment: int) -> None:
        expected = self.next_segment
        if expected is not None and segment != expected:
            self.segment_violations.append(
                violation(
                    "segment.number-increases",
                    f"segment number {expected} (one more than the last, mod 2^16)",
                    f"segment number {segment}",
                )
            )
        self.next_segment = (segment + 1) & WORD
        self.outstanding.append(segment)

    # ---------------------------------------------------------------------- asynchronous packets
    def last_processed_ok(self, number: int) -> bool:
        """``number`` can be 'the last request processed' now: sent, and not older than a request
        already answered."""
        index = self._order.get(number & WORD)
        return index is not None and index >= self._answered

    def on_async_response(
        self, number: int | None, condition: int, word2: int, word3: int
    ) -> Violation | None:
        """An asynchronous response (0203) arrived carrying request number ``number`` (None: the 1985
        guide's layout, which carries none; the mask in force now is the one that counts)."""
        if number is not None and not self.last_processed_ok(number):
            return violation(
                "async.layout",
                "the number of the last request processed (one sent and not older than the last answered)",
                f"request number {number}",
            )
        mask = (
            self.notifications if number is None else self._mask_after.get(number & WORD, self.notifications)
        )
        if condition == AsyncCondition.SEGMENT_COMPLETED:
            if not mask & _SEGMENT_BIT:
                return violation(
                    "async.only-when-requested",
                    "no segment-completed response: not asked for (0257 mask bit 1 clear)",
                    f"segment-completed for segment {word3} after request {number}",
                )
            if word2 != 0:
                return violation("async.layout", "reserved word 0", f"word2 = {word2}")
            if word3 not in self.outstanding:
                return violation(
                    "async.layout",
                    f"a queued segment not yet reported or dropped (outstanding: {self.outstanding})",
                    f"segment {word3}",
                )
            del self.outstanding[: self.outstanding.index(word3) + 1]  # segments finish in queue order
            return None
        if condition == AsyncCondition.GUARD_HIT:
            if not mask & _GUARD_BIT:
                return violation(
                    "async.only-when-requested",
                    "no guard-hit response: not asked for (0257 mask bit 0 clear)",
                    f"guard hit, guard {word3}",
                )
            if word2 not in (1, 2):
                return violation("async.layout", "word2 1 (stop) or 2 (continue)", f"word2 = {word2}")
            return None
        return violation(
            "async.codes", "condition 1 (guard hit) or 2 (segment completed)", f"condition {condition}"
        )

    def on_async_error(self, number: int, error: ErrorMessage) -> Violation | None:
        """An asynchronous error (0204) arrived.  While segments may be running it reports an abort
        (clause motion.abort): queued segments are dropped and motion is refused until a reset."""
        if not self.last_processed_ok(number):
            return violation(
                "async-error.request-number",
                "the number of the last request processed",
                f"request number {number}",
            )
        if error.severity not in ("E", "C", "BE"):
            return violation(
                "error.severity-matches-opcode", "severity E, C or BE on 0204", f"severity {error.severity}"
            )
        if self.outstanding or self.aborted is None:
            self.aborted = True
            self.outstanding.clear()
        elif self.aborted is False:
            self.aborted = None
        return None


def _combine(gate: Expectation, data: Expectation) -> Expectation:
    """A motion request: state refusals from the gate, data refusals from the request's values."""
    normal = gate.normal and data.normal
    codes = gate.codes | data.codes
    if gate.normal or not data.normal:
        clause = data.clause if not data.normal else gate.clause if not gate.normal else data.clause
    else:
        clause = gate.clause
    any_code = gate.any_code or data.any_code
    excluded = (gate.excluded | data.excluded) if any_code else frozenset()
    if not gate.normal and gate.codes == frozenset({"AWA"}):
        codes, clause = frozenset({"AWA"}), "motion.abort"  # the abort is reported first
        any_code, excluded = False, frozenset()
    why = "; ".join(w for w in (gate.why, data.why) if w)
    return Expectation(
        normal,
        codes,
        gate.command or data.command,
        any_code=any_code,
        excluded=excluded,
        clause=clause,
        why=why,
    )


def _int(value: Value) -> int:
    assert isinstance(value, int)
    return value


def _rotation_deviation(floats: Sequence[float]) -> float:
    """How far the N, O, A columns of 12 transform floats are from a proper rotation."""
    if len(floats) != 12 or not all(math.isfinite(x) for x in floats):
        return math.inf
    cols = [[float(x) for x in floats[i : i + 3]] for i in range(0, 9, 3)]
    dev = 0.0
    for i in range(3):
        for j in range(3):
            dot = sum(cols[i][k] * cols[j][k] for k in range(3))
            dev = max(dev, abs(dot - (1.0 if i == j else 0.0)))
    n, o, a = cols
    cross = (n[1] * o[2] - n[2] * o[1], n[2] * o[0] - n[0] * o[2], n[0] * o[1] - n[1] * o[0])
    det = sum(c * x for c, x in zip(cross, a, strict=True))
    return max(dev, abs(det - 1.0))


def _show(reply: AnswerSummary) -> str:
    if reply.normal:
        if reply.empty:
            return "an empty done"
        if reply.segment is not None:
            return f"a normal reply (segment {reply.segment})"
        return "a normal reply"
    assert reply.error is not None
    return f"non-fatal error {reply.error.render()!r}"
