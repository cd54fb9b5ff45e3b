"""The report of a diff: counts by class, every finding with its clause or erratum, both answers and a
reproduce line; as the console shows it, as JSON (``diff.schema.json``, next to this module), as
Markdown, as HTML (both answers side by side, the differing bytes highlighted) and as JUnit XML.

A class (a) difference (a violation) fails the diff, and so does a class (c) one (a gap in the spec)
unless ``--allow-unexplained`` keeps gaps as warnings; class (b) differences (both allowed) never do.
An unstable stream is listed apart and is no finding.  Exit statuses: :data:`manip.exit_status.EXIT_STATUSES`
(``manip-conform diff``).
"""

from __future__ import annotations

import html
import json
import shlex
from collections import Counter
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Final, cast
from xml.etree import ElementTree as ET

from manip.conformance.diff.classify import CLASSES, Finding
from manip.conformance.diff.driver import StreamResult
from manip.conformance.output.documents import ReportFormat
from manip.outfile import atomic_output
from manip.spec import SPEC

__all__ = [
    "CLASS_NAMES",
    "DIFF_FORMATS",
    "DiffReport",
    "finding_lines",
    "load_schema",
    "write_html",
    "write_json",
    "write_junit",
    "write_markdown",
]

CLASS_NAMES: Final = {
    "violation": "(a) violation",
    "allowed": "(b) both allowed",
    "unexplained": "(c) unexplained",
}


@dataclass
class DiffReport:
    """A whole diff: the two sides, the streams, what each showed."""

    a: str
    b: str
    seed: int
    length: int
    command: str
    reproduce_prefix: tuple[str, ...]
    allow_unexplained: bool = False
    results: list[StreamResult] = field(default_factory=list)
    seconds: float = 0.0
    problems: list[str] = field(default_factory=list)
    unreachable: bool = False
    interrupted: bool = False
    internal_error: str = ""

    @property
    def findings(self) -> list[Finding]:
        return [f for r in self.results for f in r.findings]

    @property
    def counts(self) -> dict[str, int]:
        counted = Counter(f.cls for f in self.findings)
        return {c: counted.get(c, 0) for c in CLASSES}

    @property
    def unstable(self) -> list[StreamResult]:
        return [r for r in self.results if r.unstable]

    @property
    def exit_code(self) -> int:
        if self.unreachable:
            return 3
        if self.interrupted or self.internal_error:
            return 4
        counts = self.counts
        failing = counts["violation"] + (0 if self.allow_unexplained else counts["unexplained"])
        return 1 if failing or self.problems else 0

    @property
    def verdict(self) -> str:
        return {0: "no difference that fails", 1: "differences", 3: "a side unreachable", 4: "interrupted"}[
            self.exit_code
        ]

    def reproduce(self, finding: Finding, result: StreamResult) -> str:
        """The command that sends the finding's stream (or its shrunk inputs) to both sides again."""
        words = [*self.reproduce_prefix, "--seed", str(self.seed)]
        if result.stream.scenario:
            words += ["--scenario", result.stream.scenario]
        elif finding.shrunk is not None:
            words += ["--inputs", ",".join(str(n) for n in finding.shrunk) or "none"]
        elif result.stream.number is not None:
            words += ["--stream", str(result.stream.number), "--length", str(self.length)]
        else:
            words += ["--inputs", ",".join(str(n) for n in result.stream.input_numbers)]
        return shlex.join(words)

    def summary_line(self) -> str:
        counts = self.counts
        parts = [f"{counts[c]} {CLASS_NAMES[c]}" for c in CLASSES]
        streams = len(self.results)
        differing = sum(bool(r.findings) for r in self.results)
        return (
            f"{streams} stream(s) of {self.length} input(s), {differing} differing, "
            f"{len(self.unstable)} unstable; " + ", ".join(parts) + f"; {self.seconds:.1f} s"
        )

    def to_json(self) -> dict[str, Any]:
        return {
            "schema_version": 1,
            "tool": "manip-conform diff",
            "spec_revision": SPEC.revision,
            "a": self.a,
            "b": self.b,
            "seed": self.seed,
            "length": self.length,
            "streams": len(self.results),
            "command": self.command,
            "duration": round(self.seconds, 3),
            "allow_unexplained": self.allow_unexplained,
            "verdict": self.verdict,
            "exit_code": self.exit_code,
            "counts": self.counts,
            "unstable": [{"stream": r.stream.label, "detail": r.unstable_detail} for r in self.unstable],
            "runaways": [{"stream": r.stream.label, "detail": d} for r in self.results for d in r.runaway],
            "not_arranged": [
                {"stream": r.stream.label, "detail": r.unarranged} for r in self.results if r.unarranged
            ],
            "not_judged": [{"stream": r.stream.label, "detail": d} for r in self.results for d in r.unjudged],
            "problems": list(self.problems),
            "findings": [self._finding_json(f, r) for r in self.results for f in r.findings],
        }

    def _finding_json(self, f: Finding, result: StreamResult) -> dict[str, Any]:
        d = f.difference
        return {
            "class": f.cls,
            "stream": f.stream,
            "input": d.number,
            "position": d.position,
            "parts": list(d.parts),
            "freedoms": list(f.freedoms),
            "names": list(f.names),
            "violator": f.violator,
            "message": f.message,
            "section": f.section,
            "follows": f.follows,
            "a": d.a.show() if d.a is not None else None,
            "b": d.b.show() if d.b is not None else None,
            "shrunk": list(f.shrunk) if f.shrunk is not None else None,
            "reproduce": self.reproduce(f, result),
        }


def load_schema() -> dict[str, Any]:
    text = resources.files("manip.conformance.diff").joinpath("diff.schema.json").read_text("utf-8")
    return cast(dict[str, Any], json.loads(text))


def write_json(report: DiffReport, path: Path) -> None:
    with atomic_output(path) as f:
        json.dump(report.to_json(), f, indent=2)
        f.write("\n")


def finding_lines(report: DiffReport, f: Finding, result: StreamResult) -> list[str]:
    """A finding in full: its class and names, both answers, the section, the reproduce line."""
    d = f.difference
    where = f"{f.stream}, input {d.number}, event {d.position}"
    names = ", ".join(f.names) or "(none)"
    parts = ", ".join(f.freedoms or d.parts)
    lines = [f"{CLASS_NAMES[f.cls]}: {where}: {parts} [{names}]"]
    if f.cls == "violation":
        if f.follows:
            lines.append(f"  follows:    the violation of {f.follows} earlier in the stream")
        else:
            other = "B" if f.violator == "A" else "A"
            lines.append(f"  broken by:  side {f.violator}: {f.message}")
            if f.violator != "both":
                lines.append(f"  conforming: side {other}'s answer")
    elif f.message:
        lines.append(f"  why:        {f.message}")
    lines.append(f"  A:          {d.a.show() if d.a is not None else '(nothing)'}")
    lines.append(f"  B:          {d.b.show() if d.b is not None else '(nothing)'}")
    if f.section:
        lines.append(f"  1985 guide: section {f.section}")
    if f.shrunk is not None:
        lines.append(f"  shrunk to:  inputs {', '.join(map(str, f.shrunk)) or '(the preamble alone)'}")
    lines.append(f"  reproduce:  {report.reproduce(f, result)}")
    return lines


def write_markdown(report: DiffReport, path: Path) -> None:
    out = [
        "# manip-conform diff",
        "",
        f"- A: `{report.a}`",
        f"- B: `{report.b}`",
        f"- seed {report.seed}; {report.summary_line()}",
        f"- verdict: **{report.verdict}** (exit {report.exit_code})",
        "",
        "| class | differences |",
        "|---|---|",
        *[f"| {CLASS_NAMES[c]} | {n} |" for c, n in report.counts.items()],
        "",
    ]
    unarranged = [r for r in report.results if r.unarranged]
    if unarranged:
        out += ["## Scenarios not compared (a condition of the world not arranged)", ""]
        out += [f"- {r.stream.label}: {r.unarranged}" for r in unarranged]
        out.append("")
    unjudged = [(r, d) for r in report.results for d in r.unjudged]
    if unjudged:
        out += ["## What a scenario's check could not judge (no finding)", ""]
        out += [f"- {r.stream.label}: {d}" for r, d in unjudged]
        out.append("")
    if report.unstable:
        out += ["## Unstable streams (no finding)", ""]
        out += [f"- {r.stream.label}: {r.unstable_detail}" for r in report.unstable]
        out.append("")
    for cls in CLASSES:
        rows = [(f, r) for r in report.results for f in r.findings if f.cls == cls]
        if not rows:
            continue
        out += [f"## {CLASS_NAMES[cls]}", ""]
        for f, r in rows:
            head, *rest = finding_lines(report, f, r)
            out += [f"### {head}", "", "```", *[line.strip() for line in rest], "```", ""]
    for problem in report.problems:
        out.append(f"- problem: {problem}")
    with atomic_output(path) as fh:
        fh.write("\n".join(out).rstrip() + "\n")


_HTML_STYLE: Final = (
    "body{font-family:sans-serif;margin:2em}table{border-collapse:collapse;width:100%}"
    "td,th{border:1px solid #ccc;padding:4px;vertical-align:top}td.bytes{font-family:monospace;"
    "word-break:break-all;width:40%}tr.violation th{background:#f8d0d0}tr.unexplained th{background:#f8ecc0}"
    "tr.allowed th{background:#d8f0d8}mark{background:#ffe066}"
)


def _marked(ours: str, theirs: str) -> str:
    """``ours`` escaped, the words that differ from ``theirs`` (by position) highlighted."""
    words, others = ours.split(" "), theirs.split(" ")
    out = []
    for i, word in enumerate(words):
        same = i < len(others) and others[i] == word
        out.append(html.escape(word) if same else f"<mark>{html.escape(word)}</mark>")
    return " ".join(out)


def write_html(report: DiffReport, path: Path) -> None:
    """Every difference, the two sides' answers side by side, the differing bytes highlighted."""
    rows = []
    for result in report.results:
        for f in result.findings:
            d = f.difference
            a = d.a.show() if d.a is not None else "(nothing)"
            b = d.b.show() if d.b is not None else "(nothing)"
            head = f"{CLASS_NAMES[f.cls]}: {f.stream}, input {d.number}: {', '.join(f.freedoms or d.parts)}"
            detail = (
                f"{', '.join(f.names)} {f.message} (1985 guide {f.section})"
                if f.section
                else ", ".join(f.names)
            )
            rows.append(
                f'<tr class="{f.cls}"><th colspan="2">{html.escape(head)}<br><small>{html.escape(detail)}'
                f"<br><code>{html.escape(report.reproduce(f, result))}</code></small></th></tr>"
                f'<tr><td class="bytes">{_marked(a, b)}</td><td class="bytes">{_marked(b, a)}</td></tr>'
            )
    counts = "".join(f"<li>{CLASS_NAMES[c]}: {n}</li>" for c, n in report.counts.items())
    unstable = "".join(
        f"<li>{html.escape(r.stream.label)}: {html.escape(r.unstable_detail)}</li>" for r in report.unstable
    )
    page = (
        f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>manip-conform diff</title>"
        f"<style>{_HTML_STYLE}</style></head><body><h1>manip-conform diff</h1>"
        f"<p>seed {report.seed}: {html.escape(report.summary_line())}; "
        f"<b>{html.escape(report.verdict)}</b> (exit {report.exit_code})</p><ul>{counts}</ul>"
        + (f"<h2>Unstable streams (no finding)</h2><ul>{unstable}</ul>" if unstable else "")
        + f"<table><tr><th>A: {html.escape(report.a)}</th><th>B: {html.escape(report.b)}</th></tr>"
        + "".join(rows)
        + "</table></body></html>\n"
    )
    with atomic_output(path) as fh:
        fh.write(page)


def write_junit(report: DiffReport, path: Path) -> None:
    """One test case per stream: failing with its violations (and gaps, unless allowed)."""
    suite = ET.Element("testsuite", name="manip-conform diff", tests=str(len(report.results)))
    failures = 0
    for result in report.results:
        case = ET.SubElement(suite, "testcase", classname="diff", name=result.stream.label)
        failing = [
            f
            for f in result.findings
            if f.cls == "violation" or (f.cls == "unexplained" and not report.allow_unexplained)
        ]
        if failing:
            failures += 1
            text = "\n\n".join("\n".join(finding_lines(report, f, result)) for f in failing)
            ET.SubElement(case, "failure", message=f"{len(failing)} difference(s)").text = text
        elif result.unstable:
            ET.SubElement(case, "skipped", message=f"unstable: {result.unstable_detail}")
        others = [f for f in result.findings if f not in failing]
        if others:
            ET.SubElement(case, "system-out").text = "\n\n".join(
                "\n".join(finding_lines(report, f, result)) for f in others
            )
    suite.set("failures", str(failures))
    with atomic_output(path, "wb") as fh:
        ET.ElementTree(suite).write(fh, encoding="utf-8", xml_declaration=True)


DIFF_FORMATS: Final[tuple[ReportFormat[DiffReport], ...]] = (
    ReportFormat("json", "Write the JSON report (diff.schema.json).", write_json),
    ReportFormat("junit", "Write JUnit XML (a test case per stream).", write_junit),
    ReportFormat("html", "Write an HTML report (both answers side by side).", write_html),
    ReportFormat("markdown", "Write a Markdown report.", write_markdown),
)
"""The diff's report formats: the options of ``manip-conform diff`` are made from them as every judging
command's are from :data:`~manip.conformance.output.documents.REPORT_FORMATS`."""
