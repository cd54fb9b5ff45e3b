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

Exit codes (:class:`ExitCode`): 0 conformant, 1 non-conformant (or a stale known-failing entry),
2 usage error, 3 target unreachable or dead before any verdict, 4 interrupted or internal error.
"""

from __future__ import annotations

import enum
import re
from collections import Counter
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Final, Literal

from manip.conformance.judge.packets import WirePacket
from manip.conformance.judge.violation import Violation
from manip.spec import SPEC
from manip.spec.model import Level

if TYPE_CHECKING:
    from manip.conformance.suite.case import Target

__all__ = [
    "JUDGED",
    "OUTCOMES",
    "CaseResult",
    "ExitCode",
    "LivenessCheck",
    "Outcome",
    "RunReport",
    "Violation",
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
    """What would judge a not-judged case, in a word: the first option its reason names (``--world``,
    ``--broken-after``), else "see its reason"."""
    found = _OPTION.search(reason)
    return found.group(0) if found else "see its reason"


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
    """The failure that ended the case first (if any), then the soft failures recorded on the way."""
    reason: str = ""
    """Why the case was skipped, or what the error was."""
    traceback: str = ""
    notes: list[str] = field(default_factory=list)
    packets: list[WirePacket] = field(default_factory=list)
    known_failing: bool = False
    reproduce: str = ""
    target: Target = "server"
    """What the case tests (the first component of a case id: server, cougar, client, puma)."""
    extensions: tuple[str, ...] = ()
    """The Puma extension opcodes the case uses where the target offers them (its declaration's)."""

    @property
    def failure(self) -> Violation | None:
        return self.violations[0] if self.violations else None


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

    def not_judged_clauses(self) -> list[str]:
        """The MUST clauses this run left unjudged: cited by a ``not-judged`` case and by no case that
        reached a verdict."""
        judged = {c for r in self.results if r.outcome in JUDGED for c in r.clauses}
        return sorted(
            {
                c
                for r in self.results
                if r.outcome == "not-judged"
                for c in r.clauses
                if c not in judged and c in SPEC.clauses and SPEC.clauses[c].level == "MUST"
            }
        )

    def not_judged_hints(self) -> dict[str, str]:
        """Each MUST clause left unjudged (:meth:`not_judged_clauses`) with what would judge it."""
        clauses = set(self.not_judged_clauses())
        hints: dict[str, str] = {}
        for result in self.results:
            if result.outcome == "not-judged":
                for clause in result.clauses:
                    if clause in clauses:
                        hints.setdefault(clause, judging_hint(result.reason))
        return dict(sorted(hints.items()))

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
