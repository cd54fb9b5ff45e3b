"""``manip-conform client [OPTIONS] -- CMD [ARGS...]``: judge a client implementation live."""

from __future__ import annotations

import asyncio
import os
import shlex
import sys

import click

from manip.commandline import FiniteFloat
from manip.conformance.cli_options import (
    check_output_paths,
    check_selection,
    known_failing_option,
    report_options,
    select_option,
    skip_option,
    strict_option,
)
from manip.conformance.client.runner import (
    DEFAULT_CLIENT_TIMEOUT,
    ClientEvents,
    ClientRunConfig,
    run_client_suite,
)
from manip.conformance.output.console import make_console, progress_bar
from manip.conformance.output.documents import ReportPaths, write_reports
from manip.conformance.output.run_console import headline, shown, summary
from manip.conformance.suite.case import Case, all_cases
from manip.conformance.suite.context import RunOptions
from manip.conformance.suite.results import CaseResult, RunReport
from manip.conformance.suite.selection import PatternError, PatternSet, match_id
from manip.exit_status import epilog

__all__ = ["client_cases", "client_command"]

EXIT_CODES_HELP = epilog("manip-conform client")


def client_cases(cases: list[Case] | None = None) -> list[Case]:
    """The cases of a client run (target ``client``: ids ``client.*``)."""
    return [c for c in (all_cases() if cases is None else cases) if c.target == "client"]


def _by_clause(patterns: tuple[str, ...], cases: list[Case]) -> list[Case]:
    if not patterns:
        return cases
    return [c for c in cases if any(match_id(p, clause) for p in patterns for clause in c.clauses)]


@click.command("client", epilog=EXIT_CODES_HELP)
@click.argument("command", nargs=-1, required=True, metavar="-- CMD [ARGS...]")
@click.option(
    "--link",
    type=click.Choice(["tcp", "chudp", "chaosd"]),
    default="tcp",
    show_default=True,
    help="The link the harness dials the judging server over.",
)
@select_option
@skip_option
@click.option(
    "--clause",
    "clauses",
    multiple=True,
    metavar="PATTERN",
    help="Run only cases declaring a clause matching PATTERN.",
)
@known_failing_option
@strict_option
@click.option("--seed", type=click.IntRange(0, 2**63 - 1), default=None, help="Seed of every random choice.")
@click.option(
    "--reply-timeout",
    type=FiniteFloat(0.1),
    default=DEFAULT_CLIENT_TIMEOUT,
    show_default=True,
    help="The timeout the harness is told to use for each reply.",
)
@click.option(
    "--deadline-scale",
    type=FiniteFloat(0.01),
    default=1.0,
    show_default=True,
    help="Multiply every deadline.",
)
@report_options
@click.option("-q", "--quiet", is_flag=True, help="No progress bar; failures and the summary only.")
def client_command(
    command: tuple[str, ...],
    link: str,
    select: tuple[str, ...],
    skip: tuple[str, ...],
    clauses: tuple[str, ...],
    known_failing: tuple[str, ...],
    strict: bool,
    seed: int | None,
    reply_timeout: float,
    deadline_scale: float,
    reports: ReportPaths,
    quiet: bool,
) -> None:
    """Judge a client: start CMD (a harness speaking docs/client-harness.md), play a scripted Puma for
    each case, and judge what the client sent and what the harness reports."""

    console = make_console()
    try:
        select_set = PatternSet.of(select, "--select")
        skip_set = PatternSet.of(skip, "--skip")
        known_set = PatternSet.of(known_failing, "--known-failing")
    except PatternError as exc:
        raise click.UsageError(str(exc)) from None
    cases = _by_clause(clauses, client_cases())
    if not cases:
        raise click.UsageError(f"--clause {' '.join(clauses)} matches no client case")
    check_selection(
        select_set, skip_set, cases, hint=" (manip-conform cases --select 'client.**' lists them)"
    )
    check_output_paths(**reports.paths)
    if seed is None:
        seed = int.from_bytes(os.urandom(4), "big")
    options = RunOptions(strict=strict, reply_timeout=reply_timeout, deadline_scale=deadline_scale)
    config = ClientRunConfig(
        argv=list(command),
        link=link,
        seed=seed,
        options=options,
        select=select_set,
        skip=skip_set,
        known_failing=known_set,
        command=shlex.join(["manip-conform", *sys.argv[1:]]),
    )
    console.print(f"manip-conform client: seed [bold]{seed}[/] (rerun with --seed {seed})")
    report = _run(config, cases, console, quiet)
    report.unwritten.extend(write_reports(report, reports))
    for problem in report.unwritten:  # a report path that cannot be written is a usage error, found late
        click.echo(f"manip-conform: {problem}", err=True)
    summary(console, report, quiet)
    unsupported = [r for r in report.results if r.outcome == "unsupported"]
    if unsupported and not quiet:
        console.print(f"{len(unsupported)} case(s) unsupported by the harness", markup=False)
    sys.exit(int(report.exit_code))


def _run(config: ClientRunConfig, cases: list[Case], console: object, quiet: bool) -> RunReport:

    progress = progress_bar(console, quiet)  # type: ignore[arg-type]
    task_id = progress.add_task("client", total=0)

    def started(chosen: list[Case]) -> None:
        progress.update(task_id, total=len(chosen))

    def finished(result: CaseResult) -> None:
        progress.advance(task_id)
        progress.update(task_id, description=result.id)
        if shown(result, quiet):
            headline(progress.console, result)

    events = ClientEvents(started=started, case_finished=finished)
    holder: list[RunReport] = []

    async def go() -> None:
        holder.append(await run_client_suite(config, cases, events))

    try:
        with progress:
            asyncio.run(go())
    except KeyboardInterrupt:
        report = RunReport(
            target=" ".join(config.argv),
            embedded=False,
            seed=config.seed,
            strict=False,
            options={},
            command=config.command,
        )
        report.interrupted = True
        report.problems.append("the run was interrupted")
        return report
    return holder[0]
