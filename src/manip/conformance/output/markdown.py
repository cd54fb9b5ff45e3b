"""The Markdown summary of a run, for CI step summaries (``$GITHUB_STEP_SUMMARY``):
``manip-conform run|verify|replay --markdown FILE`` and ``manip-conform report REPORT.json --markdown FILE``.

The verdict, the counts by verdict, how many clauses were judged and each clause's status (folded),
then the failures grouped by the clause they break (its level,
section and text), each case with its first message, and the commands that reproduce them in a code
block, one command a line.  Text from the report is escaped for Markdown and for the HTML a renderer
lets through (case output holds ``<``, ``&``, ``|``, backticks).
"""

from __future__ import annotations

import html
import re
from collections.abc import Mapping
from typing import Any, Final

from manip.conformance.output.report_view import (
    FAILING,
    OUTCOME_ORDER,
    Report,
    campaign_line,
    clause_status_entries,
    completeness_line,
    failure_groups,
    group_message,
    not_judged_line,
    plural,
    seeded,
    target_label,
)

__all__ = ["render_markdown"]

_SPECIAL: Final = re.compile(r"([\\`*_\[\]|~])")
"""What can start emphasis, code, a link or a table cell mid-line (``<``, ``>``, ``&``: HTML-escaped)."""
_MESSAGE_CHARS: Final = 200
"""A case's message is cut here (the HTML and JSON reports have it whole)."""


def _text(value: object) -> str:
    """Plain text for a Markdown line: HTML-escaped, Markdown punctuation backslashed, on one line."""
    one_line = " ".join(str(value).split())
    return _SPECIAL.sub(r"\\\1", html.escape(one_line, quote=False))


def _code(value: object) -> str:
    """An inline code span that holds ``value`` whatever backticks it has."""
    text = " ".join(str(value).split())
    fence = "`" * (max((len(m) for m in re.findall(r"`+", text)), default=0) + 1)
    pad = " " if text.startswith("`") or text.endswith("`") else ""
    return f"{fence}{pad}{text}{pad}{fence}"


def _block(lines: list[str]) -> list[str]:
    """A fenced code block (a fence longer than any backtick run in it), one command a line."""
    fence = "`" * max([3, *(len(m) + 1 for line in lines for m in re.findall(r"`+", line))])
    return [f"{fence}sh", *lines, fence]


def _message(case: Mapping[str, Any], tally: Mapping[str, Any] | None) -> str:
    text = " ".join(group_message(case, tally).split())
    return text if len(text) <= _MESSAGE_CHARS else text[: _MESSAGE_CHARS - 3] + "..."


def _status_table(report: Report) -> list[str]:
    """Every clause of the run with its status, folded (held and broken first, then what was not
    judged or not exercised, with why and what would judge it)."""
    statuses = sorted(
        clause_status_entries(report).values(),
        key=lambda s: (
            ("broken", "not-judged", "not-exercised", "held").index(str(s["status"])),
            s["clause"],
        ),
    )
    if not statuses:
        return []
    rows = [
        f"| {_code(s['clause'])} | {_text(s['level'])} | {_text(s['status'])} | "
        + (_text(f"{s['why']}; what would judge it: {s['hint']}") if s.get("why") else "")
        + " |"
        for s in statuses
    ]
    return [
        "<details><summary>Each clause's status</summary>",
        "",
        "| clause | level | status | why not judged |",
        "| --- | --- | --- | --- |",
        *rows,
        "",
        "</details>",
        "",
    ]


def render_markdown(report: Report) -> str:
    """The Markdown summary of the JSON report's data ``report``."""
    counts: Mapping[str, int] = report["counts"]
    lines = [
        f"## manip-conform: {_text(report['verdict'])} (exit {int(report['exit_code'])})",
        "",
        f"{plural(len(report['cases']), 'case')} against "
        + (target_label(report) + ", " if report.get("embedded") else f"{_code(report['target'])}, ")
        + (f"seed {int(report['seed'])}, " if seeded(report) and not report.get("embedded") else "")
        + f"{float(report.get('duration', 0.0)):.1f} s"
        + (" of virtual time" if report.get("time") == "virtual" else ""),
        "",
        "| verdict | cases |",
        "| --- | ---: |",
        *(f"| {o} | {int(counts.get(o, 0))} |" for o in OUTCOME_ORDER if counts.get(o, 0)),
        "",
    ]
    if campaign := campaign_line(report):
        lines += [_text(campaign), ""]
    if judged := completeness_line(report):
        lines += [f"**{_text(judged)}**", "", *_status_table(report)]
    for problem in [*report.get("problems", []), *report.get("unstable", [])]:
        lines.append(f"- **problem**: {_text(problem)}")
    if unjudged := not_judged_line(report):
        lines.append(f"- **not judged**: {_text(unjudged)}")
    if report.get("problems") or report.get("unstable") or unjudged:
        lines.append("")
    groups = failure_groups(report)
    if not groups:
        lines += ["No clause broke.", ""]
        return "\n".join(lines)
    lines += ["### Failures by clause", ""]
    shown: set[str] = set()  # cases whose reproduce command is listed (under the first clause they broke)
    for tally, cases in groups:
        clause = tally["clause"] if tally is not None else None
        if tally is None:
            lines.append("#### No clause: errors of the suite, stale known-failing entries")
        else:
            name = clause if clause is not None else f"(no clause: {tally['kind']})"
            tallied = ", ".join(
                f"{n} {word}"
                for n, word in (
                    (tally["failures"], "failing"),
                    (tally["warnings"], "warning" if tally["warnings"] == 1 else "warnings"),
                    (tally["known_failures"], "known failing"),
                )
                if n
            )
            section = f", \u00a7 {_text(tally['section'])}" if tally["section"] else ""
            lines += [
                f"#### {_code(name)}: {tallied} ({_text(tally['level'])}{section})",
                "",
                f"> {_text(tally['text'])}",
            ]
        lines.append("")
        lines += [f"- **{c['outcome']}** {_code(c['id'])}: {_text(_message(c, tally))}" for c in cases]
        reproduce = [
            " ".join(str(c["reproduce"]).split())
            for c in cases
            if c.get("reproduce") and c["id"] not in shown
        ]
        shown.update(c["id"] for c in cases)
        if reproduce:
            lines += ["", *_block(reproduce)]
        lines.append("")
    failing = sum(1 for c in report["cases"] if c["outcome"] in FAILING)
    lines.append(f"{failing} failing case(s) in {len(groups)} group(s).")
    return "\n".join(lines) + "\n"
