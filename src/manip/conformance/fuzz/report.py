"""What a campaign found, and its report: a :class:`~manip.conformance.suite.results.RunReport`, the
suite's one report, written by the suite's writers (JSON, JUnit, HTML, Markdown), with the campaign's
own facts in its optional ``campaign`` block (:class:`CampaignFacts`).

A *violation* is a :class:`~manip.conformance.judge.violation.Violation`, the suite's one record of a
broken clause, of one of the fuzzer's kinds (:data:`~.judge.KIND_NAMES`: crash, hang, traceback,
silent drop, wrong answer, uncounted drop); a campaign reports each kind and clause once, as a
:class:`CampaignViolation`: the violation first seen, how often it was seen, the input class it came
from, the fewest inputs found to cause it (numbers of the campaign, so ``--only`` sends them again),
their bytes, and one reproduce line.  In the ``campaign`` block each is its first violation's JSON
(:meth:`Violation.to_json`, as in the report's cases) with those fields added.

The report's cases are the input classes (``classname`` in JUnit: the layer, link, chaos or manip), each
graded by the one verdict (:func:`~manip.conformance.judge.verdict.grade`) from its violations; violations of
the target as a whole (a crash or a traceback no input could be tied to) go to the case
``target.health``.  Violations of a SHOULD, MAY or INFO clause are warnings (with ``--strict`` SHOULD ones
count); crashes, hangs, tracebacks and uncounted drops are MUST violations of the target's health.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Final, cast

from manip.conformance.fuzz.judge import FUZZ_KINDS, KIND_NAMES
from manip.conformance.judge.verdict import Outcome, grade
from manip.conformance.judge.violation import FailureKind
from manip.conformance.suite.results import CaseResult, RunReport, Violation
from manip.spec import SPEC
from manip.spec.model import Level

__all__ = [
    "CONSOLE_CUT",
    "HEALTH",
    "CampaignFacts",
    "CampaignViolation",
    "ClassTally",
    "MinimalInput",
    "class_results",
    "cut",
    "violation_json",
    "violation_text",
]

HEALTH: Final = "target.health"
"""The result under which violations of the target as a whole are reported."""


@dataclass
class ClassTally:
    """One input class in a campaign."""

    id: str
    layer: str
    sends: str
    expected: str
    clauses: tuple[str, ...]
    level: str
    hazard: str
    inputs: int = 0
    requests: int = 0
    violations: list[int] = field(default_factory=list)
    """Indices into the report's violations."""


@dataclass
class MinimalInput:
    """One input of a violation's shrunk example, as it was sent."""

    number: int
    kind: str
    note: str
    steps: list[str]
    """One line per step: what it is and its bytes in hex."""


@dataclass
class CampaignViolation:
    """One kind of failure on one clause, seen ``occurrences`` times (module docstring)."""

    violation: Violation
    """As it was first seen."""
    input_class: str
    first_batch: int
    occurrences: int = 1
    minimal: list[MinimalInput] = field(default_factory=list)
    shrunk: bool = False
    shrink_note: str = ""
    reproduce: str = ""
    counts: bool = True
    """It fails the campaign (False: a warning)."""
    followers: int = 0
    """Violations that came after it on the same connections, not judged on their own (consequences?)."""

    @property
    def kind(self) -> FailureKind:
        return self.violation.kind

    @property
    def level(self) -> Level:
        return self.violation.strength

    @property
    def spec_text(self) -> str:
        clause = self.violation.clause
        spec = SPEC.clauses.get(clause) if clause else None
        return f"{spec.text} ({spec.section})" if spec is not None else ""

    def title(self) -> str:
        v = self.violation
        where = f" [{v.clause}]" if v.clause else ""
        name = KIND_NAMES.get(v.kind, v.kind).replace(" ", "-").upper()
        return f"{name}{where} {self.input_class}: {v.message}"


@dataclass
class CampaignFacts:
    """What a campaign did and found, beyond what every report holds: the ``campaign`` block of its
    :class:`~manip.conformance.suite.results.RunReport`."""

    inputs: int = 0
    requests: int = 0
    batches: int = 0
    liveness_checks: int = 0
    liveness_failures: int = 0
    restarts: int = 0
    shrink_trials: int = 0
    tracebacks_seen: int | None = None
    bad_frames_sent: int = 0
    bad_frames_counted: int | None = None
    classes: dict[str, ClassTally] = field(default_factory=dict)
    violations: list[CampaignViolation] = field(default_factory=list)

    def counts(self) -> dict[FailureKind, int]:
        """Violations that count (not warnings) by kind, every kind present."""
        out: dict[FailureKind, int] = dict.fromkeys(FUZZ_KINDS, 0)
        for f in self.violations:
            if f.counts:
                out[f.kind] += 1
        return out

    @property
    def warnings(self) -> int:
        return sum(not f.counts for f in self.violations)

    def rate(self, duration: float) -> float:
        """Inputs per second over ``duration``."""
        return self.inputs / duration if duration > 0 else 0.0

    def summary_line(self, duration: float) -> str:
        counts = self.counts()
        kinds = ", ".join(_count(n, KIND_NAMES[kind]) for kind, n in counts.items())
        logs = (
            ""
            if self.tracebacks_seen is None
            else f"; {_count(self.tracebacks_seen, 'traceback')} in the target's log"
        )
        return (
            f"{_count(self.inputs, 'input')} ({_count(self.requests, 'request')}) in {duration:.1f} s "
            f"({self.rate(duration):.0f} inputs/s), {_count(self.batches, 'batch')}, "
            f"{self.liveness_checks - self.liveness_failures} of "
            f"{_count(self.liveness_checks, 'liveness check')} passed{logs}; {kinds}"
            + (f"; {_count(self.warnings, 'warning')}" if self.warnings else "")
        )

    def to_json(self, duration: float) -> dict[str, Any]:
        """The ``campaign`` block of the JSON report (``report.schema.json``, ``$defs/campaign``)."""
        return {
            "summary": self.summary_line(duration),
            "inputs": self.inputs,
            "requests": self.requests,
            "batches": self.batches,
            "rate": round(self.rate(duration), 3),
            "liveness": {"checks": self.liveness_checks, "failed": self.liveness_failures},
            "restarts": self.restarts,
            "shrink_trials": self.shrink_trials,
            "tracebacks_seen": self.tracebacks_seen,
            "bad_frames": {"sent": self.bad_frames_sent, "counted": self.bad_frames_counted},
            "counts": self.counts(),
            "warnings": self.warnings,
            "classes": [
                {
                    "id": c.id,
                    "layer": c.layer,
                    "sends": c.sends,
                    "expected": c.expected,
                    "inputs": c.inputs,
                    "requests": c.requests,
                    "violations": list(c.violations),
                }
                for c in self.classes.values()
            ],
            "violations": [violation_json(f) for f in self.violations],
        }


def _plural(word: str, n: int) -> str:
    if n == 1:
        return word
    return word + ("es" if word.endswith(("sh", "ch")) else "s")


def _count(n: int, word: str) -> str:
    """``1 batch``, ``3 batches``."""
    return f"{n} {_plural(word, n)}"


def violation_json(f: CampaignViolation) -> dict[str, Any]:
    """The violation's JSON, as the conformance report has it, and what the campaign adds."""
    return {
        **f.violation.to_json(),
        "level": f.level,
        "counts": f.counts,
        "spec": f.spec_text,
        "input_class": f.input_class,
        "first_batch": f.first_batch,
        "occurrences": f.occurrences,
        "minimal": [
            {"number": m.number, "class": m.kind, "note": m.note, "steps": list(m.steps)} for m in f.minimal
        ],
        "shrunk": f.shrunk,
        "shrink_note": f.shrink_note,
        "reproduce": f.reproduce,
        "followers": f.followers,
    }


def class_results(report: RunReport, facts: CampaignFacts) -> list[CaseResult]:
    """The report's cases: one per input class (and the target's health when a violation is of it),
    each graded by the one verdict from its violations."""
    health = [i for i, f in enumerate(facts.violations) if f.input_class == HEALTH]
    tallies = list(facts.classes.values())
    if health:
        tallies.append(
            ClassTally(
                HEALTH,
                "target",
                "",
                "alive and silent in its log",
                (),
                "MUST",
                "read-only",
                violations=health,
            )
        )
    results = []
    for tally in tallies:
        found = [facts.violations[i] for i in tally.violations]
        ran = tally.inputs or tally.id == HEALTH
        outcome = grade(Outcome.PASS if ran else Outcome.SKIP, [f.violation for f in found], report.strict)
        results.append(
            CaseResult(
                id=tally.id,
                clauses=tally.clauses or ("request.one-reply",),
                level=cast(Level, tally.level),
                kind="fuzz",
                hazard=tally.hazard,
                summary=f"{tally.sends}; expected: {tally.expected}",
                outcome=outcome,
                seed=report.seed,
                deadline=max(report.duration, 1.0),
                duration=0.0,
                violations=[f.violation for f in found],
                reason="no input of this class was sent" if outcome == Outcome.SKIP else "",
                notes=[f"{tally.inputs} inputs, {tally.requests} requests"],
                reproduce=next((f.reproduce for f in found), ""),
            )
        )
    return results


CONSOLE_CUT: Final = 200
"""Characters of one line of a violation the console shows (an input of 488 bytes is some 1,500 as hex);
the rest is counted, and the JSON report keeps it whole."""


def cut(line: str, limit: int = CONSOLE_CUT) -> str:
    """``line`` up to ``limit`` characters, and how many more there are (the JSON report has them)."""
    if len(line) <= limit:
        return line
    return f"{line[:limit]} ... ({len(line) - limit} more characters; whole in the JSON report)"


def violation_text(f: CampaignViolation) -> str:
    """A violation for the console: what broke, the spec, expected and actual, the shrunk input with its
    bytes, the reproduce line; a long line is cut with a count (:func:`cut`), never the reproduce line."""
    lines = [f.title()]
    v = f.violation
    if f.spec_text:
        lines.append(f"  spec:      {v.clause} ({f.level}): {f.spec_text}")
    if v.expected:
        lines.append(f"  expected:  {v.expected}")
    if v.actual:
        actual = (
            cut(v.actual)
            if "\n" not in v.actual
            else "\n" + "\n".join("    " + cut(x) for x in v.actual.splitlines())
        )
        lines.append(f"  actual:    {actual}")
    lines.append(f"  seen:      {f.occurrences} time(s), first in batch {f.first_batch}")
    if f.followers:
        lines.append(
            f"  after it:  {f.followers} more violation(s) on its connections, not judged on their own"
        )
    if f.minimal:
        state = "shrunk to" if f.shrunk else "not shrunk:"
        lines.append(
            f"  input:     {state} {len(f.minimal)} input(s){f' ({f.shrink_note})' if f.shrink_note else ''}"
        )
        for m in f.minimal[:20]:
            lines.append(cut(f"    #{m.number} {m.kind}: {m.note}"))
            lines += [cut(f"      {step}") for step in m.steps[:8]]
            if len(m.steps) > 8:
                lines.append(f"      ... {len(m.steps) - 8} more step(s)")
        if len(f.minimal) > 20:
            lines.append(f"    ... {len(f.minimal) - 20} more input(s)")
    elif f.shrink_note:
        lines.append(f"  input:     {f.shrink_note}")
    if f.reproduce:
        lines.append(f"  reproduce: {f.reproduce}")
    return "\n".join(lines)
