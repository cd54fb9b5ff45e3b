"""Reports of a run: the JSON report (its schema ships as ``report.schema.json``), JUnit XML, and the
console summary.

Every report says how completely the run judged the target: each clause its cases cite has one status
(held, broken, not judged, not exercised: :func:`~manip.conformance.suite.results.clause_statuses`,
the one rule), the JSON report as ``clause_status`` and ``completeness`` ("N of M MUST clauses
judged"), JUnit as a ``clauses`` suite of one testcase per clause.

The JSON report is versioned (``schema_version``); per case it holds the id, clauses, level, outcome,
the violations (expected / actual / bytes in hex), the duration against the deadline, the seed, the
packets both ways, and a command that reproduces the case.  JUnit XML has one ``testsuite`` per
top-level area (``server.reply``, ``server.motion``...), ``classname`` = the area and ``name`` = the case
id; ``warn`` and ``known-fail`` cases pass with a property saying so, ``skip``, ``unsupported`` and
``not-judged`` are ``<skipped>`` (the message says which).  The JSON report's ``not_judged`` lists the
MUST clauses no case could judge on the target.

Failures grouped by clause (:func:`by_clause`): how many cases broke each clause, with the clause's text
and section from the spec, so a report says first *what* is broken (``74 failures:
response.echoes-request-number``) and then where.  The JSON report has them as ``by_clause``, the
console prints one line per clause (:func:`clause_lines`), and each JUnit failure message names the
clause's text and section.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from collections import defaultdict
from collections.abc import Mapping
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any, Final

from manip.conformance.judge.verdict import CLAUSE_STATUSES, Outcome, counts, judged_counts
from manip.conformance.output.culprit import culprit_index, judged_indices, kept_indices
from manip.conformance.suite.results import CaseResult, ClauseVerdict, RunReport, Violation, completeness_text
from manip.outfile import atomic_output
from manip.spec import SPEC

__all__ = [
    "SCHEMA_VERSION",
    "ClauseTally",
    "by_clause",
    "clause_catalog",
    "clause_lines",
    "completeness_json",
    "load_schema",
    "report_json",
    "report_junit",
    "write_json",
    "write_junit",
]

SCHEMA_VERSION: Final = 1
MAX_PACKETS_IN_REPORT: Final = 200
"""Packets kept per case in the JSON report: the opening, those around each violation, then the first of
the rest (:func:`~manip.conformance.output.culprit.kept_indices`); ``packets_total`` says how many there
were, and each kept packet's ``n`` its place among them."""


def load_schema() -> dict[str, Any]:
    """The JSON Schema of the report."""
    text = resources.files("manip.conformance").joinpath("report.schema.json").read_text(encoding="utf-8")
    return dict(json.loads(text))


_NO_CLAUSE_TEXT: Final = {
    "deadline": "the case did not finish within its deadline",
}


@dataclass(frozen=True)
class ClauseTally:
    """The cases that broke one clause: counted as failures (they fail the run), warnings (SHOULD or MAY
    clauses without ``--strict``, or in a ``warn`` case) and known failures (``--known-failing``)."""

    clause: str | None
    """None for violations that cite no clause (``kind`` says what they are)."""
    kind: str
    level: str
    section: str
    text: str
    failures: int
    warnings: int
    known_failures: int
    cases: tuple[str, ...]

    @property
    def total(self) -> int:
        return self.failures + self.warnings + self.known_failures

    @property
    def name(self) -> str:
        """The clause id, or what a violation without a clause is."""
        return self.clause if self.clause is not None else f"(no clause: {self.kind})"

    def to_json(self) -> dict[str, Any]:
        return {
            "clause": self.clause,
            "kind": self.kind,
            "level": self.level,
            "section": self.section,
            "text": self.text,
            "failures": self.failures,
            "warnings": self.warnings,
            "known_failures": self.known_failures,
            "cases": list(self.cases),
        }


def _tally_key(violation: Violation) -> tuple[str | None, str]:
    return (violation.clause, "clause") if violation.clause is not None else (None, violation.kind)


def by_clause(report: RunReport) -> list[ClauseTally]:
    """Every clause some case broke, the most failures first; a case counts once per clause."""
    buckets: dict[tuple[str | None, str], dict[str, set[str]]] = defaultdict(
        lambda: {"failures": set(), "warnings": set(), "known_failures": set()}
    )
    levels: dict[tuple[str | None, str], str] = {}
    for result in report.results:
        for violation in result.violations:
            key = _tally_key(violation)
            if not result.outcome.breaks_clauses:
                continue
            if result.outcome == Outcome.KNOWN_FAIL:
                bucket = "known_failures"
            elif result.outcome == Outcome.FAIL and counts(violation, report.strict):
                bucket = "failures"
            else:
                bucket = "warnings"
            buckets[key][bucket].add(result.id)
            levels.setdefault(key, violation.strength)
    tallies = []
    for (clause, kind), groups in buckets.items():
        spec = SPEC.clauses.get(clause) if clause is not None else None
        level: str = spec.level if spec is not None else levels[(clause, kind)]
        section = spec.section if spec is not None else ""
        if spec is not None:
            text = spec.text
        else:
            text = _NO_CLAUSE_TEXT.get(kind, f"failures of kind {kind} that cite no clause")
        tallies.append(
            ClauseTally(
                clause,
                kind,
                level,
                section,
                text,
                len(groups["failures"]),
                len(groups["warnings"]),
                len(groups["known_failures"]),
                tuple(sorted(set().union(*groups.values()))),
            )
        )
    tallies.sort(key=lambda t: (-t.failures, -t.warnings, -t.known_failures, t.name))
    return tallies


def _plural(count: int, word: str) -> str:
    return f"{count} {word}" if count == 1 else f"{count} {word}s"


def clause_line(tally: ClauseTally) -> str:
    """``74 failures: response.echoes-request-number — <the clause's text> (E.3 ...)``."""
    counts = [
        _plural(n, word)
        for n, word in (
            (tally.failures, "failure"),
            (tally.warnings, "warning"),
            (tally.known_failures, "known failure"),
        )
        if n
    ]
    section = f" ({tally.section})" if tally.section else ""
    return f"{', '.join(counts)}: {tally.name} \u2014 {tally.text}{section}"


def clause_lines(report: RunReport) -> list[str]:
    """One line per broken clause (see :func:`clause_line`), the most failures first."""
    return [clause_line(t) for t in by_clause(report)]


def _packets_json(result: CaseResult) -> tuple[list[dict[str, Any]], list[int | None]]:
    """The kept packets, each numbered by its place in the transcript (from 1), and the number of each
    violation's culprit packet (None when no packet shows it)."""
    packets = result.packets
    culprits = [culprit_index(packets, v) for v in result.violations]
    kept = kept_indices(len(packets), judged_indices(packets, result.violations), MAX_PACKETS_IN_REPORT)
    shown = [{**packets[i].to_json(), "n": i + 1} for i in kept]
    return shown, [None if c is None else c + 1 for c in culprits]


def _case_json(result: CaseResult) -> dict[str, Any]:
    failure = result.failure
    packets, culprits = _packets_json(result)
    return {
        "id": result.id,
        "summary": result.summary,
        "clauses": list(result.clauses),
        "level": result.level,
        "kind": result.kind,
        "target": result.target,
        "hazard": result.hazard,
        "extensions": list(result.extensions),
        "outcome": result.outcome,
        "known_failing": result.known_failing,
        "expected": failure.expected if failure else "",
        "actual": failure.actual if failure else "",
        "bytes": failure.data.hex() if failure else "",
        "violations": [
            {**v.to_json(), "packet": culprit} for v, culprit in zip(result.violations, culprits, strict=True)
        ],
        "reason": result.reason,
        "traceback": result.traceback,
        "notes": list(result.notes),
        "duration": round(result.duration, 6),
        "deadline": result.deadline,
        **({} if result.harness_deadline is None else {"harness_deadline": result.harness_deadline}),
        "seed": result.seed,
        "reproduce": result.reproduce,
        "packets": packets,
        "packets_total": len(result.packets),
        "reached": list(result.reached),
    }


def clause_catalog(report: RunReport) -> dict[str, dict[str, str]]:
    """Level, section and text of every clause a case of the run cites, so a saved report renders
    (``manip-conform report``) with the clause texts of the spec it was judged by."""
    cited = {c for r in report.results for c in r.clauses}
    cited |= {v.clause for r in report.results for v in r.violations if v.clause is not None}
    catalog = {}
    for clause_id in sorted(cited):
        spec = SPEC.clauses.get(clause_id)
        if spec is not None:
            catalog[clause_id] = {"level": spec.level, "section": spec.section, "text": spec.text}
    return catalog


def report_json(report: RunReport) -> dict[str, Any]:
    """The report as JSON-ready data (validates against :func:`load_schema`)."""
    statuses = report.clause_statuses()
    campaign = {} if report.campaign is None else {"campaign": report.campaign.to_json(report.duration)}
    return {
        "schema_version": SCHEMA_VERSION,
        "tool": "manip-conform",
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
        "counts": report.counts(),
        "problems": list(report.problems),
        "time": report.time,
        "length_unit": report.length_unit,
        "unstable": list(report.unstable),
        "interrupted": report.interrupted,
        "internal_error": report.internal_error,
        "target_died_after": report.target_died_after,
        "liveness": [
            {"when": c.when, "alive": c.alive, "detail": c.detail, "duration": round(c.duration, 6)}
            for c in report.liveness
        ],
        "by_clause": [t.to_json() for t in by_clause(report)],
        "completeness": completeness_json(statuses),
        "clause_status": [v.to_json() for v in statuses.values()],
        "not_judged": report.not_judged_clauses(),
        "clauses": clause_catalog(report),
        "cases": [_case_json(r) for r in report.results],
        **campaign,
    }


def completeness_json(statuses: Mapping[str, ClauseVerdict]) -> dict[str, Any]:
    """Per level, how many of the run's clauses were judged (held or broken) and how many each status
    has, and the line the verdict shows (:func:`~manip.conformance.suite.results.completeness_text`)."""
    levels: dict[str, Any] = {}
    for level in ("MUST", "SHOULD", "MAY", "INFO"):
        judged, total = judged_counts(statuses, level)
        counts = {
            s: sum(v.level == level and v.status == s for v in statuses.values()) for s in CLAUSE_STATUSES
        }
        levels[level] = {"judged": judged, "total": total, **counts}
    return {"text": completeness_text(statuses), "levels": levels}


def write_json(report: RunReport, path: Path) -> None:
    """The JSON report, written whole or not at all (``OutputError`` names the path and the reason)."""
    with atomic_output(path) as f:
        f.write(json.dumps(report_json(report), indent=2) + "\n")


def _area(case_id: str) -> str:
    parts = case_id.split(".")
    return ".".join(parts[:2]) if len(parts) > 2 else parts[0]


def report_junit(report: RunReport) -> ET.Element:
    """JUnit XML (``testsuites``), one suite per area."""
    root = ET.Element("testsuites", name="manip-conform", time=f"{report.duration:.3f}")
    groups: dict[str, list[CaseResult]] = defaultdict(list)
    for result in report.results:
        groups[_area(result.id)].append(result)
    for area, results in sorted(groups.items()):
        suite = ET.SubElement(
            root,
            "testsuite",
            name=area,
            tests=str(len(results)),
            failures=str(sum(r.outcome in ("fail", "fixed") for r in results)),
            errors=str(sum(r.outcome == "error" for r in results)),
            skipped=str(sum(r.outcome in ("skip", "unsupported", "not-judged") for r in results)),
            time=f"{sum(r.duration for r in results):.3f}",
        )
        props = ET.SubElement(suite, "properties")
        ET.SubElement(props, "property", name="seed", value=str(report.seed))
        ET.SubElement(props, "property", name="target", value=report.target)
        for result in results:
            _junit_case(suite, area, result)
    _junit_clauses(root, report.clause_statuses())
    return root


def _junit_clauses(root: ET.Element, statuses: Mapping[str, ClauseVerdict]) -> None:
    """One testcase per clause of the run in a suite of its own (``clauses``): held passes, broken
    fails, not judged and not exercised are skipped saying why; the suite's properties carry the
    "N of M MUST clauses judged" line."""
    values = list(statuses.values())
    suite = ET.SubElement(
        root,
        "testsuite",
        name="clauses",
        tests=str(len(values)),
        failures=str(sum(v.status == "broken" for v in values)),
        errors="0",
        skipped=str(sum(v.status in ("not-judged", "not-exercised") for v in values)),
        time="0",
    )
    props = ET.SubElement(suite, "properties")
    ET.SubElement(props, "property", name="completeness", value=completeness_text(statuses))
    for verdict in values:
        node = ET.SubElement(
            suite, "testcase", classname=f"clauses.{verdict.level}", name=verdict.clause, time="0"
        )
        cases = ", ".join(verdict.cases)
        if verdict.status == "broken":
            ET.SubElement(node, "failure", message=f"broken by {cases}", type=verdict.clause)
        elif verdict.status != "held":
            message = f"{verdict.status}: {verdict.why}; what would judge it: {verdict.hint}"
            ET.SubElement(node, "skipped", message=message)
        else:
            ET.SubElement(node, "system-out").text = f"held in {cases}"


def _junit_case(suite: ET.Element, area: str, result: CaseResult) -> None:
    node = ET.SubElement(suite, "testcase", classname=area, name=result.id, time=f"{result.duration:.3f}")
    props = ET.SubElement(node, "properties")
    ET.SubElement(props, "property", name="clauses", value=" ".join(result.clauses))
    ET.SubElement(props, "property", name="level", value=result.level)
    ET.SubElement(props, "property", name="outcome", value=result.outcome)
    ET.SubElement(props, "property", name="seed", value=str(result.seed))
    text = _failure_text(result, with_clause_text=True)
    if result.outcome in ("fail", "fixed"):
        failure = result.failure
        message = _junit_message(failure) if failure else "listed as known failing but passed"
        element = ET.SubElement(
            node, "failure", message=message, type=failure.clause or "" if failure else "fixed"
        )
        element.text = text
    elif result.outcome == "error":
        element = ET.SubElement(node, "error", message=result.reason, type="error")
        element.text = result.traceback
    elif result.outcome == "skip":
        ET.SubElement(node, "skipped", message=result.reason)
    elif result.outcome == "unsupported":
        ET.SubElement(node, "skipped", message=f"unsupported: {result.reason}")
    elif result.outcome == "not-judged":
        ET.SubElement(node, "skipped", message=f"not judged: {result.reason}")
    elif text:
        ET.SubElement(node, "system-out").text = text


def _clause_reference(clause: str | None) -> str:
    """``the clause's text (its section)``, or "" for no clause or one the spec does not hold."""
    spec = SPEC.clauses.get(clause) if clause is not None else None
    return f"{spec.text} ({spec.section})" if spec is not None else ""


def _junit_message(failure: Violation) -> str:
    """The failure's message, then the clause it breaks: a CI page shows only this line."""
    reference = _clause_reference(failure.clause)
    if not reference:
        return failure.message
    return f"{failure.message} \u2014 {failure.clause}: {reference}"


def _failure_text(result: CaseResult, *, with_clause_text: bool = False) -> str:
    lines = []
    for v in result.violations:
        lines.append(f"[{v.clause or '-'}] ({v.level}) {v.message}")
        if with_clause_text and (reference := _clause_reference(v.clause)):
            lines.append(f"  clause:   {reference}")
        if v.expected:
            lines.append(f"  expected: {v.expected}")
        if v.actual:
            lines.append(f"  actual:   {v.actual}")
        if v.data:
            lines.append(f"  bytes:    {v.data.hex(' ')}")
    if lines:
        lines.append(f"reproduce: {result.reproduce}")
    return "\n".join(lines)


def write_junit(report: RunReport, path: Path) -> None:
    """The JUnit XML, written whole or not at all (``OutputError`` names the path and the reason)."""
    write_xml(report_junit(report), path)


def write_xml(root: ET.Element, path: Path) -> None:
    tree = ET.ElementTree(root)
    ET.indent(tree)
    with atomic_output(path, "wb") as f:
        tree.write(f, encoding="utf-8", xml_declaration=True)


def failure_text(result: CaseResult) -> str:
    """Expected / actual / bytes / reproduce lines of a case, for the console."""
    return _failure_text(result)
