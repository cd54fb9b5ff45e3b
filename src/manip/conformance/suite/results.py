"""The results of a run as values: one :class:`CaseResult` per case, one :class:`RunReport` per run.

Outcomes (``Outcome``):

* ``pass``: every clause the case checks held;
* ``fail``: a MUST clause broke, or (with ``--strict``) a SHOULD clause;
* ``warn``: only SHOULD/MAY/INFO clauses broke, without ``--strict`` (they do not fail the run);
* ``error``: the suite itself failed (an exception in the case); the traceback is kept;
* ``skip``: not applicable (hazard not allowed on hardware, a capability the target lacks...);
* ``known-fail``: failed (or erred) and listed in ``--known-failing``; does not fail the run;
* ``fixed``: listed in ``--known-failing`` but passed: the entry is stale and fails the run;
* ``unsupported``: a client case needing an operation, link or feature the harness does not declare
  (``manip-conform client``); never a pass, and it does not fail the run;
* ``not-judged``: the case applies, but cannot judge its clauses on this target: it needs a condition of
  the arm's world and the run has no world that arranges it (``--world``).  Its reason says what would
  judge it; never a pass, and it does not fail the run, but the verdict line counts the MUST clauses
  left unjudged (:meth:`RunReport.not_judged_clauses`).

Clauses (:func:`clause_statuses`, the one rule every report uses): each clause the run's cases cite is
held (a check reached it), broken, not judged (why, what would judge it) or not exercised; the verdict
line says "N of M MUST clauses judged" (:func:`completeness_text`).

Exit codes (:class:`ExitCode`): 0 conformant, 1 non-conformant (or a stale known-failing entry),
2 usage error, 3 target unreachable (nothing it sent reached the run), 4 interrupted or internal error.
"""

from __future__ import annotations

import enum
import re
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Final, Literal

from manip.conformance.judge.packets import WirePacket
from manip.conformance.judge.violation import Violation
from manip.spec import SPEC
from manip.spec.model import LEVELS, Level

if TYPE_CHECKING:
    from manip.conformance.suite.case import Target

__all__ = [
    "CLAUSE_STATUSES",
    "JUDGED",
    "OUTCOMES",
    "CaseResult",
    "ClauseStatus",
    "ClauseVerdict",
    "ExitCode",
    "LivenessCheck",
    "Outcome",
    "RunReport",
    "Violation",
    "clause_statuses",
    "completeness_text",
    "conclude",
    "judged_counts",
    "judging_hint",
]

Outcome = Literal["pass", "fail", "warn", "error", "skip", "known-fail", "fixed", "unsupported", "not-judged"]
OUTCOMES: Final[tuple[str, ...]] = (
    "pass",
    "fail",
    "warn",
    "error",
    "skip",
    "known-fail",
    "fixed",
    "unsupported",
    "not-judged",
)
JUDGED: Final = frozenset({"pass", "fail", "warn", "known-fail", "fixed"})
"""Outcomes of a case that ran to a verdict on its clauses."""


_OPTION = re.compile(r"--[a-z][a-z-]+")


def judging_hint(reason: str) -> str:
    """What would judge a not-judged case, in a word: a target serving manip's Puma extensions when the
    reason is a refused extension, else the first option its reason names (``--world``,
    ``--broken-after``), else "see its reason"."""
    if "a Puma extension" in reason:
        return "a target that serves the Puma extensions"
    found = _OPTION.search(reason)
    return found.group(0) if found else "see its reason"


ClauseStatus = Literal["held", "broken", "not-judged", "not-exercised"]
CLAUSE_STATUSES: Final[tuple[str, ...]] = ("held", "broken", "not-judged", "not-exercised")
_VERDICT_OUTCOMES: Final = frozenset({"fail", "warn", "known-fail"})
"""Outcomes whose violations break their clauses (an ``error`` is the suite's, not the target's)."""
_UNJUDGING_OUTCOMES: Final = frozenset({"not-judged", "unsupported", "error"})
"""Outcomes of a case that applies but could not judge its clauses."""


@dataclass(frozen=True)
class ClauseVerdict:
    """One clause's status in a run (:func:`clause_statuses`)."""

    clause: str
    level: Level
    status: ClauseStatus
    cases: tuple[str, ...]
    """The cases behind the status: those that broke it, reached it, or cited it."""
    why: str = ""
    """For ``not-judged`` and ``not-exercised``: why not."""
    hint: str = ""
    """For ``not-judged`` and ``not-exercised``: what would judge it."""

    def to_json(self) -> dict[str, object]:
        return {
            "clause": self.clause,
            "level": self.level,
            "status": self.status,
            "cases": list(self.cases),
            "why": self.why,
            "hint": self.hint,
        }


def clause_statuses(results: Iterable[CaseResult]) -> dict[str, ClauseVerdict]:
    """Every clause the run's cases cite or broke, with exactly one status (the one rule every report
    uses):

    * ``broken``: a case that reached a verdict (fail, warn, known-fail) reports a violation of it;
    * ``held``: not broken, and a case that reached a verdict actually evaluated it (``reached``);
    * ``not-judged``: neither, and a case citing it could not judge it on this target (not-judged,
      unsupported, or the suite erred): ``why`` is that case's reason, ``hint`` what would judge it;
    * ``not-exercised``: none of these: its cases ran without reaching it, or did not run (skipped).
    """
    results = list(results)
    level_of = {c: SPEC.clauses[c].level for r in results for c in r.clauses if c in SPEC.clauses}
    broken: dict[str, list[str]] = {}
    for r in results:
        if r.outcome in _VERDICT_OUTCOMES:
            for v in r.violations:
                if v.clause is not None:
                    broken.setdefault(v.clause, []).append(r.id)
                    level_of.setdefault(
                        v.clause, SPEC.clauses[v.clause].level if v.clause in SPEC.clauses else v.strength
                    )
    verdicts: dict[str, ClauseVerdict] = {}
    for clause in sorted(level_of):
        level = level_of[clause]
        citing = [r for r in results if clause in r.clauses]
        if clause in broken:
            verdicts[clause] = ClauseVerdict(clause, level, "broken", tuple(sorted(set(broken[clause]))))
            continue
        reached = [r.id for r in citing if r.outcome in JUDGED and clause in _reached(r)]
        if reached:
            verdicts[clause] = ClauseVerdict(clause, level, "held", tuple(reached))
            continue
        verdicts[clause] = _unjudged(clause, level, citing)
    return verdicts


_WHOLE_RECORDING: Final = frozenset({"replay", "verify", "fuzz"})
"""Results judged whole, not by a case's checks (``verify``, ``replay``: a recording; ``fuzz``: every
exchange of an input class): their checks run over all of it, so every clause they cite was evaluated."""


def _reached(result: CaseResult) -> Iterable[str]:
    return result.clauses if result.kind in _WHOLE_RECORDING else result.reached


def _unjudged(clause: str, level: Level, citing: list[CaseResult]) -> ClauseVerdict:
    """The status of a clause no case broke or reached: not judged, or not exercised."""
    cases = tuple(r.id for r in citing)
    unjudging = [r for r in citing if r.outcome in _UNJUDGING_OUTCOMES]
    if unjudging:
        first = unjudging[0]
        why = first.reason if first.outcome != "error" else f"the suite erred in {first.id}: {first.reason}"
        hint = judging_hint(first.reason) if first.outcome != "error" else "a suite without that error"
        return ClauseVerdict(clause, level, "not-judged", cases, f"{first.id}: {why}", hint)
    ran = [r for r in citing if r.outcome in JUDGED]
    if ran:
        why = f"{', '.join(r.id for r in ran)} ran without a check reaching it"
        return ClauseVerdict(
            clause,
            level,
            "not-exercised",
            cases,
            why,
            "more examples (--max-examples) or another random draw",
        )
    reasons = sorted({r.reason for r in citing if r.reason})
    why = "its cases did not run" + (f" ({'; '.join(reasons)})" if reasons else "")
    return ClauseVerdict(clause, level, "not-exercised", cases, why, "a target its cases apply to")


def judged_counts(verdicts: Mapping[str, ClauseVerdict], level: Level) -> tuple[int, int]:
    """(judged, all) among the clauses of ``level``: judged means held or broken."""
    mine = [v for v in verdicts.values() if v.level == level]
    return sum(v.status in ("held", "broken") for v in mine), len(mine)


def completeness_text(verdicts: Mapping[str, ClauseVerdict]) -> str:
    """``N of M MUST clauses judged`` (and the SHOULD clauses' when there are any), for verdict lines."""
    parts = []
    for level in ("MUST", "SHOULD"):
        judged, total = judged_counts(verdicts, level)
        if total or level == "MUST":
            parts.append(f"{judged} of {total} {level} clauses judged")
    return ", ".join(parts)


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
        return {name: counter[name] for name in OUTCOMES}

    @property
    def exit_code(self) -> ExitCode:
        counts = self.counts()
        if self.unwritten:  # a report path that cannot be written is a usage error, found late
            return ExitCode.USAGE
        if self.unreachable:
            return ExitCode.UNREACHABLE
        if self.interrupted or self.internal_error or self.unstable:
            return ExitCode.INTERNAL
        if counts["fail"] or counts["fixed"] or self.problems:
            return ExitCode.NON_CONFORMANT
        if counts["error"]:
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
    that stopped it (if any) first, then every one recorded on the way, the strongest first.  A counted
    violation (MUST, and SHOULD with ``strict``) fails the case even when it went on to skip, to be
    not judged, or to stumble on what the violation left (an exception after it is noted, not an
    error of the suite); weaker ones make a passing case ``warn``.  The one rule of every runner."""
    counted = {"MUST", "SHOULD"} if strict else {"MUST"}
    if failure is not None:
        result.violations.append(failure)
    # the strongest first (stable): the case's failure is its first MUST violation, wherever it came
    result.violations += sorted(recorded, key=lambda v: LEVELS.index(v.strength))
    fails = any(v.level in counted for v in result.violations)
    if result.outcome == "error" and fails and not result.reason.startswith("bug of the suite"):
        result.notes.append(f"the case could not go on after its violations: {result.reason}")
        result.reason, result.traceback = "", ""
        result.outcome = "fail"
    elif result.outcome in ("pass", "skip", "not-judged", "unsupported") and fails:
        if result.outcome != "pass":
            result.notes.append(f"it then ended {result.outcome}: {result.reason}")
            result.reason = ""
        result.outcome = "fail"
    elif result.outcome == "pass" and result.violations:
        result.outcome = "warn"
    if result.known_failing:
        if result.outcome in ("fail", "error"):
            result.outcome = "known-fail"
        elif result.outcome in ("pass", "warn"):
            result.outcome = "fixed"
