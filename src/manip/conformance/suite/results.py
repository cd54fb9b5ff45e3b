"""The results of a run as values: one :class:`CaseResult` per case, one :class:`RunReport` per run.

What an outcome means (:class:`~manip.conformance.judge.verdict.Outcome`), which violations count, a
case's outcome from its violations (:func:`conclude`, through
:func:`~manip.conformance.judge.verdict.grade`) and each clause's status in a run
(:meth:`RunReport.clause_statuses`) are the verdict module's (:mod:`manip.conformance.judge.verdict`),
the one rule every runner and report uses; the verdict line says "N of M MUST clauses judged"
(:func:`~manip.conformance.judge.verdict.completeness_text`).

Exit codes (:class:`ExitCode`): 0 conformant, 1 non-conformant (or a stale known-failing entry),
2 usage error, 3 target unreachable (nothing it sent reached the run), 4 interrupted or internal error.
"""

from __future__ import annotations

import enum
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

from manip.conformance.judge.packets import WirePacket
from manip.conformance.judge.verdict import (
    ClauseVerdict,
    Outcome,
    clause_statuses,
    completeness_text,
    grade,
    judging_hint,
    strongest_first,
)
from manip.conformance.judge.violation import Violation
from manip.spec.model import Level

if TYPE_CHECKING:
    from manip.conformance.suite.case import Target


__all__ = [
    "CampaignBlock",
    "CaseResult",
    "ClauseVerdict",
    "ExitCode",
    "LivenessCheck",
    "Outcome",
    "RunReport",
    "Violation",
    "clause_statuses",
    "completeness_text",
    "conclude",
    "judging_hint",
]


class ExitCode(enum.IntEnum):
    CONFORMANT = 0
    NON_CONFORMANT = 1
    USAGE = 2
    UNREACHABLE = 3
    INTERNAL = 4


@dataclass
class CaseResult:
    id: str
    clauses: tuple[str, ...]
    level: Level
    kind: str
    hazard: str
    summary: str
    outcome: Outcome
    seed: int
    deadline: float
    duration: float = 0.0
    violations: list[Violation] = field(default_factory=list)
    """The failure that stopped the case (if any), then every violation recorded on the way."""
    reached: tuple[str, ...] = ()
    """The declared clauses the case's checks actually evaluated (``ctx.reached``): a cited clause
    not among them was not exercised by this case, whatever its outcome."""
    reason: str = ""
    """Why the case was skipped, or what the error was."""
    traceback: str = ""
    notes: list[str] = field(default_factory=list)
    packets: list[WirePacket] = field(default_factory=list)
    known_failing: bool = False
    reproduce: str = ""
    target: Target = "server"
    """What the case tests (the first component of a case id: server, cougar, client, puma)."""
    harness_deadline: float | None = None
    """Client cases: the contract's deadline for the harness (docs/client-harness.md section 5, the sum
    over the case's plays), apart from :attr:`deadline`, the case's own time budget; None elsewhere."""
    extensions: tuple[str, ...] = ()
    """The Puma extension opcodes the case uses where the target offers them (its declaration's)."""

    def __post_init__(self) -> None:
        self.outcome = Outcome(self.outcome)  # its facts, for a result made with the outcome's name

    @property
    def failure(self) -> Violation | None:
        return self.violations[0] if self.violations else None

    def timing(self) -> str:
        """How long the case took against its time budget, and, for a client case, the contract's
        deadline for the harness told apart from it."""
        text = f"took {self.duration:.2f} s of its {self.deadline:g} s time budget"
        if self.harness_deadline is not None:
            text += f"; the contract's deadline for the harness was {self.harness_deadline:g} s"
        return text


@dataclass(frozen=True)
class LivenessCheck:
    """A liveness probe: connect, initial RESPONSE, one read-only request answered."""

    when: str
    """``before``, ``after:CASE_ID`` or ``end``."""
    alive: bool
    detail: str
    duration: float


class CampaignBlock(Protocol):
    """The facts a fuzz campaign adds to its report (``manip.conformance.fuzz.report.CampaignFacts``):
    the optional ``campaign`` block of the JSON report, and its one-line summary."""

    def to_json(self, duration: float) -> dict[str, Any]: ...

    def summary_line(self, duration: float) -> str: ...


@dataclass
class RunReport:
    target: str
    embedded: bool
    seed: int
    strict: bool
    options: dict[str, object]
    command: str
    started: str = ""
    duration: float = 0.0
    results: list[CaseResult] = field(default_factory=list)
    liveness: list[LivenessCheck] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)
    """Run-level failures: stale known-failing entries, the target dying, an interruption."""
    unwritten: list[str] = field(default_factory=list)
    """Reports asked for that could not be written (a message each: the path and why): exit 2."""
    interrupted: bool = False
    internal_error: str = ""
    target_died_after: str | None = None
    unreachable: bool = False
    capture_unusable: bool = False
    """With ``unreachable``: what failed was the capture a replay or verify reads, not the target."""
    time: str = "real"
    """The clock the run used: ``real`` (wall clock) or ``virtual`` (the embedded server simulated on the
    runner's loop; case durations and packet times are then simulated seconds)."""
    length_unit: str = "mm"
    """The unit the target's lengths were taken to be in (``--length-unit``, erratum ``units``)."""
    unstable: list[str] = field(default_factory=list)
    """Suite problems found by ``--repeat``: cases whose verdict changed between seeds or between two
    runs of one seed (exit 4: a verdict that depends on the draw cannot be trusted)."""
    campaign: CampaignBlock | None = None
    """A fuzz campaign's own facts (``manip-conform fuzz``); None for every other command."""

    def capture_problem(self, problem: str) -> None:
        """The capture cannot be used (unreadable, or without the sessions asked for): exit 3."""
        self.unreachable = self.capture_unusable = True
        self.problems.append(problem)

    def clause_statuses(self) -> dict[str, ClauseVerdict]:
        """Every clause of the run with its one status (:func:`clause_statuses`)."""
        return clause_statuses(self.results)

    def not_judged_clauses(self) -> list[str]:
        """The MUST clauses this run left unjudged (status ``not-judged``)."""
        return list(self.not_judged_hints())

    def not_judged_hints(self) -> dict[str, str]:
        """Each MUST clause left unjudged (:meth:`not_judged_clauses`) with what would judge it."""
        return {
            v.clause: v.hint
            for v in self.clause_statuses().values()
            if v.status == "not-judged" and v.level == "MUST"
        }

    def counts(self) -> dict[str, int]:
        counter: Counter[str] = Counter(r.outcome for r in self.results)
        return {str(name): counter[name] for name in Outcome}

    @property
    def exit_code(self) -> ExitCode:
        failing = {r.outcome for r in self.results if r.outcome.fails_run}
        if self.unwritten:  # a report path that cannot be written is a usage error, found late
            return ExitCode.USAGE
        if self.unreachable:
            return ExitCode.UNREACHABLE
        if self.interrupted or self.internal_error or self.unstable:
            return ExitCode.INTERNAL
        if failing - {Outcome.ERROR} or self.problems:
            return ExitCode.NON_CONFORMANT
        if failing:  # only errors: they fail the run, but they are the suite's, not the target's
            return ExitCode.INTERNAL
        return ExitCode.CONFORMANT

    @property
    def verdict(self) -> str:
        return {
            ExitCode.CONFORMANT: "conformant",
            ExitCode.NON_CONFORMANT: "non-conformant",
            ExitCode.USAGE: "usage error",
            ExitCode.UNREACHABLE: "capture unusable" if self.capture_unusable else "target unreachable",
            ExitCode.INTERNAL: "interrupted"
            if self.interrupted
            else ("unstable suite" if self.unstable and not self.internal_error else "internal error"),
        }[self.exit_code]


def conclude(
    result: CaseResult, failure: Violation | None, recorded: Sequence[Violation], strict: bool
) -> None:
    """A case's outcome from how it ended (``result.outcome`` so far) and what it found: the violation
    that stopped it (if any) first, then every one recorded on the way, the strongest first; the
    outcome is :func:`~manip.conformance.judge.verdict.grade`'s.  When its violations override how it
    ended (an error, a skip, not judged), that end is kept as a note."""
    if failure is not None:
        result.violations.append(failure)
    # the strongest first (stable): the case's failure is its first MUST violation, wherever it came
    result.violations += strongest_first(recorded)
    ended = result.outcome
    graded = grade(
        ended,
        result.violations,
        strict,
        suite_bug=result.reason.startswith("bug of the suite"),
    )
    if graded == Outcome.FAIL and ended == Outcome.ERROR:
        result.notes.append(f"the case could not go on after its violations: {result.reason}")
        result.reason, result.traceback = "", ""
    elif graded in (Outcome.FAIL, Outcome.WARN) and ended not in (Outcome.PASS, graded):
        result.notes.append(f"it then ended {ended}: {result.reason}")
        result.reason = ""
    result.outcome = graded
    if result.known_failing:
        result.outcome = grade(graded, (), strict, known_failing=True)
