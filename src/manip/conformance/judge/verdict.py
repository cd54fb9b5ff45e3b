"""The one verdict of every judging command (``run``, ``client``, ``verify``, ``replay``, ``fuzz``): what
an outcome means, which violations count, the outcome a result's violations give it, and each clause's
status in a run.

* :class:`Outcome`: a case's (or a verify family's, or a fuzz input class's) outcome, carrying its facts:
  its place in the order a reader looks at outcomes (:attr:`~Outcome.rank`), whether it fails the run,
  whether it needs a reader's attention, whether it is a verdict on its clauses (judged).
* :func:`counts`: whether a violation fails what it is found in: a MUST one always, a SHOULD one under
  ``--strict``.  A violation whose level is not known counts as a MUST (an unknown level is never
  quietly a warning).
* :func:`grade`: the outcome a result ends with, from how it ended and the violations it found.
* :func:`clause_statuses`: every clause a run's results cite, held, broken, not judged or not exercised.

Nothing else decides any of these: the runners, the report writers and the documents read them here.
"""

from __future__ import annotations

import enum
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Final, Literal, NamedTuple, Protocol

from manip.conformance.judge.violation import Violation
from manip.spec import SPEC
from manip.spec.model import LEVELS, Level

__all__ = [
    "CLAUSE_STATUSES",
    "ClauseStatus",
    "ClauseVerdict",
    "Judged",
    "Outcome",
    "clause_statuses",
    "completeness_text",
    "counts",
    "grade",
    "judged_counts",
    "judging_hint",
    "strongest_first",
]


class _Facts(NamedTuple):
    rank: int
    fails_run: bool
    needs_attention: bool
    judged: bool
    breaks_clauses: bool
    unjudging: bool


class Outcome(enum.StrEnum):
    """How a case ended.  The members are listed in the order reports count them.

    * ``pass``: every clause the case checks held;
    * ``fail``: a violation counted (:func:`counts`);
    * ``warn``: only violations that do not count (SHOULD without ``--strict``, MAY, INFO);
    * ``error``: the suite itself failed (an exception in the case); the traceback is kept;
    * ``skip``: not applicable (hazard not allowed on hardware, a case of another link...);
    * ``known-fail``: failed (or erred) and listed in ``--known-failing``; does not fail the run;
    * ``fixed``: listed in ``--known-failing`` but passed: the entry is stale and fails the run;
    * ``unsupported``: a client case needing what the harness does not declare; never a pass;
    * ``not-judged``: the case applies but cannot judge its clauses on this target; its reason says what
      would judge it.
    """

    PASS = "pass"
    FAIL = "fail"
    WARN = "warn"
    ERROR = "error"
    SKIP = "skip"
    KNOWN_FAIL = "known-fail"
    FIXED = "fixed"
    UNSUPPORTED = "unsupported"
    NOT_JUDGED = "not-judged"

    @property
    def rank(self) -> int:
        """Its place when outcomes are listed for a reader, those needing attention first (0)."""
        return _FACTS[self].rank

    @property
    def fails_run(self) -> bool:
        """It fails the run (``fail``, ``error``, ``fixed``)."""
        return _FACTS[self].fails_run

    @property
    def needs_attention(self) -> bool:
        """A reader needs to look at it (the rest are quiet: passed, skipped, not run...)."""
        return _FACTS[self].needs_attention

    @property
    def judged(self) -> bool:
        """The case ran to a verdict on its clauses."""
        return _FACTS[self].judged

    @property
    def breaks_clauses(self) -> bool:
        """Its violations break their clauses (an ``error`` is the suite's, not the target's)."""
        return _FACTS[self].breaks_clauses

    @property
    def unjudging(self) -> bool:
        """The case applies but could not judge its clauses (not judged, unsupported, the suite erred)."""
        return _FACTS[self].unjudging

    @classmethod
    def by_rank(cls) -> tuple[Outcome, ...]:
        """Every outcome, those needing attention first."""
        return tuple(sorted(cls, key=lambda o: o.rank))


_FACTS: Final[Mapping[Outcome, _Facts]] = {
    #                                rank  fails  attention judged breaks unjudging
    Outcome.FAIL: _Facts(0, True, True, True, True, False),
    Outcome.ERROR: _Facts(1, True, True, False, False, True),
    Outcome.FIXED: _Facts(2, True, True, True, False, False),
    Outcome.WARN: _Facts(3, False, True, True, True, False),
    Outcome.KNOWN_FAIL: _Facts(4, False, True, True, True, False),
    Outcome.NOT_JUDGED: _Facts(5, False, False, False, False, True),
    Outcome.SKIP: _Facts(6, False, False, False, False, False),
    Outcome.UNSUPPORTED: _Facts(7, False, False, False, False, True),
    Outcome.PASS: _Facts(8, False, False, True, False, False),
}
if set(_FACTS) != set(Outcome):  # a new outcome must state its facts
    raise RuntimeError(f"outcomes without facts: {set(Outcome) - set(_FACTS)}")


def counts(violation: Violation, strict: bool) -> bool:
    """Whether ``violation`` fails what it is found in: MUST (or a level not known), or SHOULD under
    ``strict``."""
    return violation.strength == "MUST" or (strict and violation.strength == "SHOULD")


def strongest_first(violations: Iterable[Violation]) -> list[Violation]:
    """``violations`` the strongest level first (stable: their order within one level is kept)."""
    return sorted(violations, key=lambda v: LEVELS.index(v.strength))


_REGRADED: Final = frozenset({Outcome.PASS, Outcome.SKIP, Outcome.NOT_JUDGED, Outcome.UNSUPPORTED})
"""How a case may end that its violations override: a violation seen is never hidden behind them."""


def grade(
    ended: Outcome,
    violations: Sequence[Violation],
    strict: bool,
    *,
    known_failing: bool = False,
    suite_bug: bool = False,
) -> Outcome:
    """The outcome of a result that ``ended`` so (``pass`` when nothing stopped it) with ``violations``.

    A counted violation (:func:`counts`) fails it, even when it went on to skip, to be not judged, or
    to stumble on what the violation left (an ``error`` after it, unless ``suite_bug``: a bug of the
    suite stays an error); any other violation makes it ``warn`` where it would have passed, skipped or
    not been judged.  A ``known_failing`` result that failed (or erred) is ``known-fail``, one that
    passed (or only warned) ``fixed``."""
    outcome = ended
    fails = any(counts(v, strict) for v in violations)
    if ended == Outcome.ERROR and fails and not suite_bug:
        outcome = Outcome.FAIL
    elif ended in _REGRADED and violations:
        outcome = Outcome.FAIL if fails else Outcome.WARN
    if known_failing:
        if outcome in (Outcome.FAIL, Outcome.ERROR):
            return Outcome.KNOWN_FAIL
        if outcome in (Outcome.PASS, Outcome.WARN):
            return Outcome.FIXED
    return outcome


# --------------------------------------------------------------------------------- clause statuses


class Judged(Protocol):
    """What :func:`clause_statuses` reads of a result (a :class:`~manip.conformance.suite.results.
    CaseResult`)."""

    @property
    def id(self) -> str: ...
    @property
    def clauses(self) -> tuple[str, ...]: ...
    @property
    def kind(self) -> str: ...
    @property
    def outcome(self) -> Outcome: ...
    @property
    def reason(self) -> str: ...
    @property
    def reached(self) -> tuple[str, ...]: ...
    @property
    def violations(self) -> list[Violation]: ...


ClauseStatus = Literal["held", "broken", "not-judged", "not-exercised"]
CLAUSE_STATUSES: Final[tuple[ClauseStatus, ...]] = ("held", "broken", "not-judged", "not-exercised")

_OPTION = re.compile(r"--[a-z][a-z-]+")


def judging_hint(reason: str) -> str:
    """What would judge a not-judged case, in a word: a target serving manip's Puma extensions when the
    reason is a refused extension, else the first option its reason names (``--world``,
    ``--broken-after``), else "see its reason"."""
    if "a Puma extension" in reason:
        return "a target that serves the Puma extensions"
    found = _OPTION.search(reason)
    return found.group(0) if found else "see its reason"


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


def clause_statuses(results: Iterable[Judged]) -> dict[str, ClauseVerdict]:
    """Every clause the run's results cite or broke, with exactly one status:

    * ``broken``: a result whose outcome breaks clauses (fail, warn, known-fail) reports a violation
      of it;
    * ``held``: not broken, and a judged result actually evaluated it (``reached``);
    * ``not-judged``: neither, and a result citing it could not judge it on this target (not judged,
      unsupported, or the suite erred): ``why`` is that result's reason, ``hint`` what would judge it;
    * ``not-exercised``: none of these: its cases ran without reaching it, or did not run (skipped).
    """
    results = list(results)
    level_of = {c: SPEC.clauses[c].level for r in results for c in r.clauses if c in SPEC.clauses}
    broken: dict[str, list[str]] = {}
    for r in results:
        if Outcome(r.outcome).breaks_clauses:
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
        reached = [r.id for r in citing if Outcome(r.outcome).judged and clause in _reached(r)]
        if reached:
            verdicts[clause] = ClauseVerdict(clause, level, "held", tuple(reached))
            continue
        verdicts[clause] = _unjudged(clause, level, citing)
    return verdicts


_WHOLE_RECORDING: Final = frozenset({"replay", "verify", "fuzz"})
"""Results judged whole, not by a case's checks (``verify``, ``replay``: a recording; ``fuzz``: every
exchange of an input class): their checks run over all of it, so every clause they cite was evaluated."""


def _reached(result: Judged) -> Iterable[str]:
    return result.clauses if result.kind in _WHOLE_RECORDING else result.reached


def _unjudged(clause: str, level: Level, citing: list[Judged]) -> ClauseVerdict:
    """The status of a clause no result broke or reached: not judged, or not exercised."""
    cases = tuple(r.id for r in citing)
    unjudging = [r for r in citing if Outcome(r.outcome).unjudging]
    if unjudging:
        first = unjudging[0]
        erred = first.outcome == Outcome.ERROR
        why = first.reason if not erred else f"the suite erred in {first.id}: {first.reason}"
        hint = judging_hint(first.reason) if not erred else "a suite without that error"
        return ClauseVerdict(clause, level, "not-judged", cases, f"{first.id}: {why}", hint)
    ran = [r for r in citing if Outcome(r.outcome).judged]
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
    why = "its cases did not run: " + "; ".join(
        f"{r.id} ({r.outcome}: {r.reason})" if r.reason else f"{r.id} ({r.outcome})" for r in citing
    )
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
