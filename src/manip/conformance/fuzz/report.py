"""The report of a campaign: one result per input class, every finding with its shrunk input, as the
console shows it, as JSON (``fuzz.schema.json``, next to this module) and as JUnit XML.

A *finding* is a :class:`~manip.conformance.judge.violation.Violation`, the suite's one record of a
broken clause, of one of the fuzzer's kinds (:data:`~.judge.KIND_NAMES`: crash, hang, traceback,
silent drop, wrong answer, uncounted drop); a campaign reports each kind and clause once, as a
:class:`CampaignViolation`: the violation first seen, how often it was seen, the input class it came
from, the fewest inputs found to cause it (numbers of the campaign, so ``--only`` sends them again),
their bytes, and one reproduce line.  In the JSON report a finding is the violation's JSON
(:meth:`Violation.to_json`, as in the conformance report) with those fields added.

Findings of a SHOULD, MAY or INFO clause are warnings (with ``--strict`` SHOULD ones count); crashes,
hangs, tracebacks and uncounted drops always count.  Exit codes: 0 no finding, 1 findings, 2 usage,
3 target unreachable (no liveness check ever passed), 4 interrupted or an internal error.

JUnit: one test case per input class (``classname`` its layer: link, chaos, manip), failing with its
findings; findings of the target as a whole (a crash or a traceback no input could be tied to) go to
the case ``target.health``.  It is made with the conformance report's writer
(:func:`manip.conformance.output.report.report_junit`), one
:class:`~manip.conformance.suite.results.CaseResult` per class.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Final, cast

from manip.conformance.fuzz.judge import FUZZ_KINDS, KIND_NAMES
from manip.conformance.judge.verdict import Outcome, grade
from manip.conformance.judge.violation import FailureKind
from manip.conformance.output.report import report_junit, write_xml
from manip.conformance.suite.results import CaseResult, ExitCode, RunReport, Violation
from manip.outfile import atomic_output
from manip.spec import SPEC
from manip.spec.model import Level

__all__ = [
    "CONSOLE_CUT",
    "HEALTH",
    "SCHEMA_VERSION",
    "CampaignViolation",
    "ClassTally",
    "FuzzReport",
    "MinimalInput",
    "as_run_report",
    "cut",
    "finding_json",
    "finding_text",
    "load_schema",
    "report_json",
    "write_json",
    "write_junit",
]

SCHEMA_VERSION: Final = 1
HEALTH: Final = "target.health"
"""The result findings of the target as a whole are reported under."""


def load_schema() -> dict[str, Any]:
    text = resources.files("manip.conformance.fuzz").joinpath("fuzz.schema.json").read_text(encoding="utf-8")
    return dict(json.loads(text))


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
    findings: list[int] = field(default_factory=list)
    """Indices into the report's findings."""


@dataclass
class MinimalInput:
    """One input of a finding's shrunk example, as it was sent."""

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
    """Findings that came after it on the same connections, not judged on their own (consequences?)."""

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
class FuzzReport:
    """Everything a campaign did and found."""

    target: str
    embedded: bool
    seed: int
    command: str
    options: dict[str, Any]
    strict: bool = False
    started: str = ""
    duration: float = 0.0
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
    findings: list[CampaignViolation] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)
    interrupted: bool = False
    internal_error: str = ""
    unreachable: bool = False

    def counts(self) -> dict[FailureKind, int]:
        """Findings (not warnings) by kind, every kind present."""
        out: dict[FailureKind, int] = dict.fromkeys(FUZZ_KINDS, 0)
        for f in self.findings:
            if f.counts:
                out[f.kind] += 1
        return out

    @property
    def warnings(self) -> int:
        return sum(not f.counts for f in self.findings)

    @property
    def exit_code(self) -> ExitCode:
        if self.unreachable:
            return ExitCode.UNREACHABLE
        if self.interrupted or self.internal_error:
            return ExitCode.INTERNAL
        if any(self.counts().values()) or self.problems:
            return ExitCode.NON_CONFORMANT
        return ExitCode.CONFORMANT

    @property
    def verdict(self) -> str:
        return {
            ExitCode.CONFORMANT: "no findings",
            ExitCode.NON_CONFORMANT: "findings",
            ExitCode.UNREACHABLE: "target unreachable",
            ExitCode.INTERNAL: "interrupted" if self.interrupted else "internal error",
            ExitCode.USAGE: "usage error",
        }[self.exit_code]

    @property
    def rate(self) -> float:
        return self.inputs / self.duration if self.duration > 0 else 0.0

    def summary_line(self) -> str:
        counts = self.counts()
        kinds = ", ".join(f"{n} {_plural(KIND_NAMES[kind], n)}" for kind, n in counts.items())
        logs = (
            ""
            if self.tracebacks_seen is None
            else f"; {self.tracebacks_seen} traceback(s) in the target's log"
        )
        return (
            f"{self.inputs} inputs ({self.requests} requests) in {self.duration:.1f} s "
            f"({self.rate:.0f} inputs/s), {self.batches} batches, "
            f"{self.liveness_checks - self.liveness_failures} of {self.liveness_checks} liveness checks "
            f"passed{logs}; {kinds}" + (f"; {self.warnings} warning(s)" if self.warnings else "")
        )


def _plural(word: str, n: int) -> str:
    if n == 1:
        return word
    return word + ("es" if word.endswith("sh") else "s")


def finding_json(f: CampaignViolation) -> dict[str, Any]:
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


def report_json(report: FuzzReport) -> dict[str, Any]:
    """The report as JSON-ready data (validates against :func:`load_schema`)."""
    return {
        "schema_version": SCHEMA_VERSION,
        "tool": "manip-conform fuzz",
        "spec_revision": SPEC.revision,
        "target": report.target,
        "embedded": report.embedded,
        "command": report.command,
        "started": report.started,
        "duration": round(report.duration, 6),
        "seed": report.seed,
        "strict": report.strict,
        "options": report.options,
        "verdict": report.verdict,
        "exit_code": int(report.exit_code),
        "inputs": report.inputs,
        "requests": report.requests,
        "batches": report.batches,
        "rate": round(report.rate, 3),
        "liveness": {"checks": report.liveness_checks, "failed": report.liveness_failures},
        "restarts": report.restarts,
        "shrink_trials": report.shrink_trials,
        "tracebacks_seen": report.tracebacks_seen,
        "bad_frames": {"sent": report.bad_frames_sent, "counted": report.bad_frames_counted},
        "counts": report.counts(),
        "warnings": report.warnings,
        "problems": list(report.problems),
        "interrupted": report.interrupted,
        "internal_error": report.internal_error,
        "classes": [
            {
                "id": c.id,
                "layer": c.layer,
                "sends": c.sends,
                "expected": c.expected,
                "clauses": list(c.clauses),
                "level": c.level,
                "hazard": c.hazard,
                "inputs": c.inputs,
                "requests": c.requests,
                "outcome": _outcome(report, c),
                "findings": list(c.findings),
            }
            for c in report.classes.values()
        ],
        "findings": [finding_json(f) for f in report.findings],
    }


def _outcome(report: FuzzReport, tally: ClassTally) -> Outcome:
    found = [report.findings[i].violation for i in tally.findings]
    return grade(Outcome.PASS if tally.inputs or tally.id == HEALTH else Outcome.SKIP, found, report.strict)


def write_json(report: FuzzReport, path: Path) -> None:
    """The JSON report, written whole or not at all (``OutputError`` names the path and the reason)."""
    with atomic_output(path) as f:
        f.write(json.dumps(report_json(report), indent=2) + "\n")


def as_run_report(report: FuzzReport) -> RunReport:
    """The campaign in the conformance report's shape: one case per input class (and the target's health)."""
    run = RunReport(
        target=report.target,
        embedded=report.embedded,
        seed=report.seed,
        strict=report.strict,
        options=report.options,
        command=report.command,
        started=report.started,
        duration=report.duration,
    )
    health = [i for i, f in enumerate(report.findings) if f.input_class == HEALTH]
    tallies = list(report.classes.values())
    if health:
        tallies.append(
            ClassTally(
                HEALTH, "target", "", "alive and silent in its log", (), "MUST", "read-only", findings=health
            )
        )
    for tally in tallies:
        found = [report.findings[i] for i in tally.findings]
        outcome = _outcome(report, tally)
        result = CaseResult(
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
            reason="no input of this class was sent" if outcome == "skip" else "",
            notes=[f"{tally.inputs} inputs, {tally.requests} requests"],
            reproduce=next((f.reproduce for f in found), ""),
        )
        run.results.append(result)
    return run


def write_junit(report: FuzzReport, path: Path) -> None:
    """The JUnit XML, written whole or not at all (``OutputError`` names the path and the reason)."""
    write_xml(report_junit(as_run_report(report)), path)


CONSOLE_CUT: Final = 200
"""Characters of one line of a finding the console shows (an input of 488 bytes is some 1,500 as hex);
the rest is counted, and the JSON report keeps it whole."""


def cut(line: str, limit: int = CONSOLE_CUT) -> str:
    """``line`` up to ``limit`` characters, and how many more there are (the JSON report has them)."""
    if len(line) <= limit:
        return line
    return f"{line[:limit]} ... ({len(line) - limit} more characters; whole in the JSON report)"


def finding_text(f: CampaignViolation) -> str:
    """A finding for the console: what broke, the spec, expected and actual, the shrunk input with its
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
            f"  after it:  {f.followers} more finding(s) on its connections, not judged on their own"
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
