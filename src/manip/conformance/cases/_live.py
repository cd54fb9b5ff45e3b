"""Helpers of the property and stateful cases (no cases are declared here): what the target says about
its arm, one request/answer exchange as the model sees it, and failures that carry their evidence."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from manip.arm.kinematics import PUMA600, JointLimits, Joints
from manip.codecs.errors import CodecError
from manip.codecs.lisp import LispValue
from manip.codecs.messages import ErrorReply, decode_error
from manip.conformance.checks import (
    Finding,
    WirePacket,
    description_operations,
    multi_text,
    parse_description,
    word,
)
from manip.conformance.context import Answer, CaseContext, Probe
from manip.conformance.invariants import TRANSCRIPT
from manip.conformance.model import Reply
from manip.spec import SPEC
from manip.spec.constants import ServerOp

__all__ = [
    "Evidence",
    "TargetArm",
    "describe_target",
    "lenient_error",
    "must",
    "reply_view",
    "stated_limits",
]


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
    if limits is None:
        ctx.note("describe self gives no usable :joint-limits; assuming the PUMA 600's")
        return TargetArm(dof=dof, operations=operations)
    return TargetArm(limits=limits, declared=True, dof=dof, operations=operations)


def reply_view(answer: Answer) -> Reply:
    """The model's view of an answer (a RESPONSE, or the decoded error string of an error)."""
    first = answer.first
    if first.opcode == ServerOp.RESPONSE:
        op = SPEC.requests.get(answer.request.opcode)
        segment = None
        if op is not None and op.response.kind == "segment" and len(first.data) == 4:
            segment = word(first.data, 2)
        return Reply(True, empty=len(first.data) == 2, segment=segment)
    decoded = lenient_error(first.opcode, first.data)
    return Reply(False, error=None if decoded is None else decoded.error)


def lenient_error(opcode: int, data: bytes) -> ErrorReply | None:
    """An error packet decoded with its numbers aligned, or else unaligned (a misaligned argument list
    is the format checker's finding, not a reason to misjudge the error); None when neither reads."""
    for aligned in (True, False):
        try:
            return decode_error(opcode, data, align_args=aligned)
        except CodecError:
            continue
    return None


def must(findings: Iterable[Finding]) -> list[Finding]:
    """The findings that break a MUST clause."""
    return [f for f in findings if f.level == "MUST"]


@dataclass(eq=False)
class Evidence(AssertionError):  # noqa: N818 - a failed example, not an error of the suite
    """A failed example: the clause, expected and actual, and the packets that showed it.

    ``invariant``: the suite invariant that found it (a checker's finding, a probe's failure), passed
    on to ``ctx.fail`` so that a clause the case does not declare is attributed to it."""

    clause: str
    message: str
    expected: str
    actual: str
    data: bytes = b""
    packets: list[WirePacket] = field(default_factory=list)
    example: list[WirePacket] = field(default_factory=list)
    """Every packet of the example that failed, both ways (set by the case's runner; ``packets`` are the
    ones among them that show the failure)."""
    drawn: str = ""
    """What Hypothesis drew for that example, as the report shows it (set by the case's runner)."""
    invariant: str | None = None

    def __post_init__(self) -> None:
        super().__init__(f"[{self.clause}] {self.message}")

    @classmethod
    def of(cls, finding: Finding, packets: Iterable[WirePacket] = ()) -> Evidence:
        """A checker's finding (the transcript invariant's checkers)."""
        return cls(
            finding.clause,
            finding.message,
            finding.expected,
            finding.actual,
            finding.data,
            list(packets),
            invariant=TRANSCRIPT.name,
        )
