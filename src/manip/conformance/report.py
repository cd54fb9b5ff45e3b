"""Reports of a run: the JSON report (its schema ships as ``report.schema.json``), JUnit XML, and the
console summary.

The JSON report is versioned (``schema_version``); per case it holds the id, clauses, level, outcome,
the violations (expected / actual / bytes in hex), the duration against the deadline, the seed, the
packets both ways, and a command that reproduces the case.  JUnit XML has one ``testsuite`` per
top-level area (``server.reply``, ``server.motion``...), ``classname`` = the area and ``name`` = the case
id; ``warn`` and ``known-fail`` cases pass with a property saying so, ``skip`` is ``<skipped>``.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from collections import defaultdict
from importlib import resources
from pathlib import Path
from typing import Any, Final

from manip.conformance.results import CaseResult, RunReport
from manip.spec import SPEC

__all__ = ["SCHEMA_VERSION", "load_schema", "report_json", "report_junit", "write_json", "write_junit"]

SCHEMA_VERSION: Final = 1
MAX_PACKETS_IN_REPORT: Final = 200
"""Packets kept per case in the JSON report (the first ones; a note says when more were cut)."""


def load_schema() -> dict[str, Any]:
    """The JSON Schema of the report."""
    text = resources.files("manip.conformance").joinpath("report.schema.json").read_text(encoding="utf-8")
    return dict(json.loads(text))


def _case_json(result: CaseResult) -> dict[str, Any]:
    failure = result.failure
    return {
        "id": result.id,
        "summary": result.summary,
        "clauses": list(result.clauses),
        "level": result.level,
        "kind": result.kind,
        "hazard": result.hazard,
        "outcome": result.outcome,
        "known_failing": result.known_failing,
        "expected": failure.expected if failure else "",
        "actual": failure.actual if failure else "",
        "bytes": failure.data.hex() if failure else "",
        "violations": [v.to_json() for v in result.violations],
        "reason": result.reason,
        "traceback": result.traceback,
        "notes": list(result.notes),
        "duration": round(result.duration, 6),
        "deadline": result.deadline,
        "seed": result.seed,
        "reproduce": result.reproduce,
        "packets": [p.to_json() for p in result.packets[:MAX_PACKETS_IN_REPORT]],
        "packets_total": len(result.packets),
    }


def report_json(report: RunReport) -> dict[str, Any]:
    """The report as JSON-ready data (validates against :func:`load_schema`)."""
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
        "unstable": list(report.unstable),
        "interrupted": report.interrupted,
        "internal_error": report.internal_error,
        "target_died_after": report.target_died_after,
        "liveness": [
            {"when": c.when, "alive": c.alive, "detail": c.detail, "duration": round(c.duration, 6)}
            for c in report.liveness
        ],
        "cases": [_case_json(r) for r in report.results],
    }


def write_json(report: RunReport, path: Path) -> None:
    path.write_text(json.dumps(report_json(report), indent=2) + "\n", encoding="utf-8")


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
            skipped=str(sum(r.outcome == "skip" for r in results)),
            time=f"{sum(r.duration for r in results):.3f}",
        )
        props = ET.SubElement(suite, "properties")
        ET.SubElement(props, "property", name="seed", value=str(report.seed))
        ET.SubElement(props, "property", name="target", value=report.target)
        for result in results:
            _junit_case(suite, area, result)
    return root


def _junit_case(suite: ET.Element, area: str, result: CaseResult) -> None:
    node = ET.SubElement(suite, "testcase", classname=area, name=result.id, time=f"{result.duration:.3f}")
    props = ET.SubElement(node, "properties")
    ET.SubElement(props, "property", name="clauses", value=" ".join(result.clauses))
    ET.SubElement(props, "property", name="level", value=result.level)
    ET.SubElement(props, "property", name="outcome", value=result.outcome)
    ET.SubElement(props, "property", name="seed", value=str(result.seed))
    text = _failure_text(result)
    if result.outcome in ("fail", "fixed"):
        failure = result.failure
        message = failure.message if failure else "listed as known failing but passed"
        element = ET.SubElement(
            node, "failure", message=message, type=failure.clause or "" if failure else "fixed"
        )
        element.text = text
    elif result.outcome == "error":
        element = ET.SubElement(node, "error", message=result.reason, type="error")
        element.text = result.traceback
    elif result.outcome == "skip":
        ET.SubElement(node, "skipped", message=result.reason)
    elif text:
        ET.SubElement(node, "system-out").text = text


def _failure_text(result: CaseResult) -> str:
    lines = []
    for v in result.violations:
        lines.append(f"[{v.clause or '-'}] ({v.level}) {v.message}")
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
    tree = ET.ElementTree(report_junit(report))
    ET.indent(tree)
    tree.write(path, encoding="utf-8", xml_declaration=True)


def failure_text(result: CaseResult) -> str:
    """Expected / actual / bytes / reproduce lines of a case, for the console."""
    return _failure_text(result)
