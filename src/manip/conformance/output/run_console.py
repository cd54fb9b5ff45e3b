"""What a run prints on the console: a line per case as it ends, then the broken clauses, each failure in
full, the problems and the verdict line (``manip-conform run`` and ``manip-conform client``; ``verify`` and
``replay`` print their broken clauses the same way)."""

from __future__ import annotations

from rich.console import Console
from rich.markup import escape

from manip.conformance.judge.verdict import Outcome
from manip.conformance.output.report import clause_lines, failure_text
from manip.conformance.suite.results import CaseResult, ExitCode, RunReport, completeness_text
from manip.conformance.suite.world import WITHOUT_WORLD

__all__ = ["OUTCOME_STYLE", "counts_text", "details", "headline", "print_by_clause", "shown", "summary"]


OUTCOME_STYLE: dict[str, str] = {
    "pass": "green",
    "fail": "bold red",
    "warn": "yellow",
    "error": "bold magenta",
    "skip": "dim",
    "known-fail": "cyan",
    "fixed": "bold red",
    "unsupported": "blue",
    "not-judged": "bold blue",
}
"""The console style of each outcome."""


def counts_text(report: RunReport) -> str:
    return ", ".join(f"{v} {k}" for k, v in report.counts().items() if v) or "no cases"


def shown(result: CaseResult, quiet: bool) -> bool:
    """Whether the summary shows the case in full: it fails the run, or warns (not with ``--quiet``)."""
    return result.outcome.fails_run or (result.outcome == Outcome.WARN and not quiet)


def headline(console: Console, result: CaseResult) -> None:
    style = OUTCOME_STYLE[result.outcome]
    clauses = sorted({v.clause for v in result.violations if v.clause})
    broke = f" [{', '.join(clauses)}]" if clauses else ""
    head = f"{escape(result.id)} ({result.duration:.2f} s){escape(broke)}"
    console.print(f"[{style}]{result.outcome.upper():>10}[/] {head}")


def details(console: Console, report: RunReport, quiet: bool) -> None:
    """Each failing (or warning, fixed, erring) case in full: what was expected, what came, the bytes,
    the command that reproduces it."""
    for result in report.results:
        if not shown(result, quiet):
            continue
        headline(console, result)
        body = failure_text(result) if result.outcome != "error" else result.traceback.rstrip()
        if result.outcome == "fixed":
            body = "listed in --known-failing but passed: remove the entry"
        if body:
            console.print(body, markup=False, highlight=False)


def print_by_clause(console: Console, report: RunReport) -> None:
    """One line per broken clause (count, id, text, section), under a heading; nothing if none broke."""
    lines = clause_lines(report)
    if lines:
        console.print("[bold]broken clauses[/]:")
        for line in lines:
            console.print(f"  {line}", markup=False)


def summary(console: Console, report: RunReport, quiet: bool = False) -> None:
    """After the run: the broken clauses (one line each), then every failure in full, then problems and
    the verdict with how completely it judged ("N of M MUST clauses judged"), then the MUST clauses
    not judged (with what would judge each) and not exercised."""
    counts = report.counts()
    parts = [f"[{OUTCOME_STYLE[k]}]{v} {k}[/]" for k, v in counts.items() if v]
    print_by_clause(console, report)
    details(console, report, quiet)
    for problem in report.problems:
        console.print(f"[bold red]problem[/]: {escape(problem)}")
    for problem in report.unstable:
        console.print(f"[bold magenta]unstable[/]: {escape(problem)}")
    verdict_style = "bold green" if report.exit_code == ExitCode.CONFORMANT else "bold red"
    shown = ", ".join(parts) or "no cases"
    statuses = report.clause_statuses()
    unjudged = report.not_judged_hints()
    console.print(
        f"[{verdict_style}]{report.verdict}[/] (exit {int(report.exit_code)}): {shown}"
        f" in {report.duration:.1f} s; seed {report.seed}"
        + ("; virtual time" if report.time == "virtual" else "")
        + (f"; {completeness_text(statuses)}" if statuses else "")
    )
    unexercised: dict[str, list[str]] = {}
    for v in statuses.values():
        if v.status == "not-exercised" and v.level == "MUST":
            unexercised.setdefault(v.why, []).append(v.clause)
    if unexercised:
        console.print(f"[{OUTCOME_STYLE['skip']}]not exercised[/] (no check of the run reached them):")
        for why, clauses in unexercised.items():  # one line per reason: what would reach them
            console.print(f"  {escape(', '.join(clauses))}: {escape(why)}")
    if unjudged:
        listed = ", ".join(f"{clause} ({hint})" for clause, hint in unjudged.items())
        console.print(
            f"[{OUTCOME_STYLE['not-judged']}]not judged[/]: {escape(listed)};"
            " what would judge each is in brackets"
        )
        if "--world" in unjudged.values():
            console.print(f"--world: {escape(WITHOUT_WORLD)}")
    slow = [r for r in report.results if r.deadline and r.duration > 0.8 * r.deadline]
    for r in slow:
        console.print(f"[yellow]slow[/]: {escape(r.id)} {escape(r.timing())}")
