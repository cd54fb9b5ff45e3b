"""``manip-conform``: run the conformance suite, list its cases, map clause coverage.

Commands::

    manip-conform run [HOST] [options]     run the suite (no HOST: against the embedded reference server)
    manip-conform cases [--format table|json] [--select P]...
    manip-conform coverage [--format table|json] [--party P]...
    manip-conform report REPORT.json [--html FILE] [--markdown FILE]

Exit codes of ``run`` (documented in ``--help``):

    0  conformant: no MUST failure (nor SHOULD failure with --strict), no stale known-failing entry
    1  non-conformant: a failure, a stale known-failing entry, or the target died during the run
    2  usage error (bad option, pattern, address or pattern file; a --select matching no case; an
       option of a target not chosen; a report or capture path that cannot be written)
    3  target unreachable, or dead before any case reached a verdict
    4  interrupted, an internal error of the suite, or a verdict that changed with the seed (``--repeat``;
       a partial report is still written)

``coverage`` exits 1 when a MUST clause in scope has no case.  The group leaves room for more
subcommands (``replay``, ``verify``) added by other modules: they register on :data:`main`.
"""

from __future__ import annotations

import contextlib
import difflib
import json
import os
import shlex
import sys
import traceback
from collections.abc import AsyncIterator, Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, TypeVar

import click
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from manip.commandline import configure_logging, version_option
from manip.conformance.cli_options import (
    json_option,
    junit_option,
    known_failing_option,
    select_option,
    skip_option,
    strict_option,
)
from manip.conformance.client.cli import client_command
from manip.conformance.cougar.target import CougarTarget, cougar_cases, liveness_check
from manip.conformance.fuzz.cli import fuzz_command
from manip.conformance.output.console import make_console, progress_bar
from manip.conformance.output.coverage import DEFAULT_PARTIES, coverage, gaps
from manip.conformance.output.documents import ReportError, document_options, render_saved, write_documents
from manip.conformance.output.report import failure_text, write_json, write_junit
from manip.conformance.puma.target import (
    DEFAULT_WRIST_LISTEN,
    DEFAULT_WRIST_WAIT,
    PumaTarget,
    PumaUnreachableError,
    puma_cases,
)
from manip.conformance.replay.cli import (
    check_output_paths,
    given,
    print_by_clause,
    recording,
    replay_command,
    verify_command,
)
from manip.conformance.suite.case import Case, all_cases
from manip.conformance.suite.context import DEFAULT_REPLY_TIMEOUT, RunOptions
from manip.conformance.suite.embedded import EmbeddedServer, simulated_environment
from manip.conformance.suite.results import CaseResult, ExitCode, LivenessCheck, RunReport
from manip.conformance.suite.runner import RunConfig, RunEvents, Runner
from manip.conformance.suite.selection import PatternError, PatternSet, match_id
from manip.conformance.suite.stability import instability, repeat_seeds
from manip.conformance.suite.world import WITHOUT_WORLD, WorldError
from manip.conformance.suite.world_link import DEFAULT_ANSWER_TIMEOUT, open_world
from manip.conformance.suite.world_prompt import PROMPT_TIMEOUT, PromptWorld, check_terminal
from manip.exit_status import epilog
from manip.links import AddressError, parse_address, virtual_clock
from manip.reference_server import FaultSet, ServerConfig
from manip.spec import SPEC, UnknownClauseError

__all__ = ["main"]

EXIT_CODES_HELP = epilog("manip-conform run")

F = TypeVar("F", bound=Callable[..., Any])

_NOT_WITH_COUGAR = {
    "record": "records Chaos connections",
    "broken_after": "is the timer of a Chaos target",
    "max_examples": "sets the examples of the property cases of a server run",
}
"""Options of ``run`` that mean nothing for a Cougar target: giving one with ``--cougar`` is an error."""

TABLE_WIDTH = 160
VIRTUAL_BROKEN_AFTER = 10.0
"""The embedded server's broken-connection timer in a virtual-time run without --broken-after (s)."""
"""On a terminal, the ``cases`` and ``coverage`` tables are laid out at least this wide."""

_STYLE = {
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


def _number_option(name: str, kind: click.ParamType[Any, Any], default: float, help: str) -> Callable[[F], F]:
    """A numeric option whose default is shown in --help."""
    return click.option(name, type=kind, default=default, show_default=True, help=help)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@version_option("manip-conform")
def main() -> None:
    """Conformance suite for the Chaos manipulator protocol (MIT Puma/Cougar, 1985): its servers and
    clients, and both ends of the Cougar wrist link."""
    configure_logging()


# ----------------------------------------------------------------------------------------------- run


@main.command(epilog=EXIT_CODES_HELP)
@click.argument("host", required=False)
@select_option
@skip_option
@click.option(
    "--clause",
    "clauses",
    multiple=True,
    metavar="ID",
    help="Run the cases that check clause ID (repeatable; with --select, a case either selects runs).",
)
@known_failing_option
@strict_option
@click.option(
    "--seed",
    type=click.IntRange(0, 2**63 - 1),
    default=None,
    help="Seed of every random choice (printed always; the same seed gives the same run).",
)
@_number_option("--max-examples", click.IntRange(1), 25, "Examples per property-based case.")
@click.option(
    "--target",
    "target_kind",
    type=click.Choice(["sim", "hardware"]),
    default="sim",
    show_default=True,
    help="hardware: motion and power cases are left out unless --allow-motion.",
)
@click.option("--allow-motion", is_flag=True, help="With --target hardware, run motion and power cases too.")
@_number_option(
    "--reply-timeout", click.FloatRange(0.01), DEFAULT_REPLY_TIMEOUT, "Seconds to wait for each reply."
)
@_number_option(
    "--deadline-scale", click.FloatRange(0.01), 1.0, "Multiply every case deadline (slow links, real arms)."
)
@_number_option(
    "--target-time-scale",
    click.FloatRange(min=0.01),
    1.0,
    "HOST's arm runs this many times faster than real time (a simulated server started with --time-scale):"
    " its 16 ms servo cycle is judged at that rate (erratum server-time-scale).",
)
@click.option(
    "--broken-after",
    type=click.FloatRange(min=0.1),
    default=None,
    metavar="SECONDS",
    help="The target's broken-connection timer (90 s by default, the ITS Chaos NCP's: the 1985 guide "
    "gives none; erratum ncp-timers): server.ncp.broken goes silent "
    "that long and checks the connection was given up.  Without it that case is skipped, except against "
    "the embedded server in virtual time, whose timer is then 10 s (silence costs little there).  With the "
    "embedded server, the server gets this timer too (below 5 s the other NCP cases, which keep quiet "
    "for up to 3 s on purpose, may lose their connections).",
)
@json_option
@junit_option
@document_options
@click.option(
    "--server-fault",
    "server_faults",
    multiple=True,
    metavar="NAME[=ARG]",
    help="Embedded server only: switch on a fault of the reference server (see manip-server --help).",
)
@click.option(
    "--cougar",
    "cougar",
    is_flag=False,
    flag_value="sim",
    default=None,
    metavar="URL",
    help="Check a Cougar instead of a server: tcp://HOST:PORT of a DRV-11J Cougar (manip-cougar), or "
    "'sim' (the default value) for the simulated one in-process.  Only cougar cases run.",
)
@click.option(
    "--cougar-fault",
    "cougar_faults",
    multiple=True,
    metavar="NAME",
    help="With --cougar sim: switch on a defect of the simulated Cougar (see manip-cougar --help).",
)
@click.option(
    "--puma",
    "puma",
    is_flag=True,
    help="Judge the Puma's side of the wrist link: the suite plays Cougar on the emulated DRV-11J for the "
    "Puma server at HOST (started with manip-server --cougar pointing at --wrist-listen, after the suite) "
    "or, without HOST, for the embedded reference server.  Only puma cases run.",
)
@click.option(
    "--wrist-listen",
    "wrist_listen",
    default=DEFAULT_WRIST_LISTEN,
    show_default=True,
    metavar="URL",
    help="With --puma HOST: where the judging Cougar listens (tcp://HOST:PORT) for the Puma's wrist link.",
)
@click.option(
    "--wrist-wait",
    "wrist_wait",
    type=click.FloatRange(min=0.1),
    default=DEFAULT_WRIST_WAIT,
    show_default=True,
    metavar="SECONDS",
    help="With --puma HOST: how long the judging Cougar waits for the Puma's wrist link.",
)
@click.option(
    "--record",
    "record",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Record every Chaos connection of the run (client side) to an MCAP capture FILE "
    "(judge it with: manip-conform verify FILE).",
)
@click.option(
    "--time",
    "time_mode",
    type=click.Choice(["virtual", "real"]),
    default=None,
    help="virtual (the default without HOST): the embedded server and the suite share one simulated "
    "clock that skips idle time; the same seed gives the same verdict and the same packets.  real (the "
    "default, and the only mode, with HOST): wall-clock time, the embedded server on its own thread.",
)
@click.option(
    "--repeat",
    type=click.IntRange(1),
    default=1,
    show_default=True,
    metavar="N",
    help="A stability gate: run the selection with N seeds (--seed first, then seeds derived from it) "
    "and once more with the first; a case whose verdict changes between seeds, or between the two runs "
    "of one seed (in virtual time: whose packets change), is a problem of the suite: exit 4.",
)
@click.option(
    "--world",
    "world",
    default=None,
    metavar="CMD_OR_URL",
    help="HOST's world, which arranges what the protocol cannot provoke (an obstacle, a calibration "
    "failure, a silent wrist...; contract 2, docs/world-harness.md): tcp://HOST:PORT of a world that "
    "listens (manip-server --world tcp://127.0.0.1:0), a command line the suite starts, or 'prompt' (an "
    "operator at a terminal arranges each condition by hand).  Without it the cases that need one end "
    "not-judged.  The embedded server has its own.",
)
@click.option(
    "--world-timeout",
    "world_timeout",
    type=click.FloatRange(min=0.1),
    default=None,
    metavar="SECONDS",
    help="How long the world has to arrange or clear a condition (default 30 s; 300 s with --world prompt).",
)
@click.option("-q", "--quiet", is_flag=True, help="No progress bar; failures and the summary only.")
def run(
    host: str | None,
    select: tuple[str, ...],
    skip: tuple[str, ...],
    clauses: tuple[str, ...],
    known_failing: tuple[str, ...],
    strict: bool,
    seed: int | None,
    max_examples: int,
    target_kind: str,
    allow_motion: bool,
    reply_timeout: float,
    deadline_scale: float,
    target_time_scale: float,
    broken_after: float | None,
    json_path: Path | None,
    junit_path: Path | None,
    html_path: Path | None,
    markdown_path: Path | None,
    server_faults: tuple[str, ...],
    cougar: str | None,
    cougar_faults: tuple[str, ...],
    puma: bool,
    wrist_listen: str,
    wrist_wait: float,
    record: Path | None,
    time_mode: str | None,
    repeat: int,
    world: str | None,
    world_timeout: float | None,
    quiet: bool,
) -> None:
    """Run the suite against HOST (a link address: tcp://HOST:PORT, chudp://HOST:PORT?addr=OCTAL,
    chaosd:///PATH, or HOST[:PORT] for tcp).  Without HOST the embedded reference server is started
    on a free loopback port and the suite runs against it.  With --cougar the Cougar cases run against
    a Cougar over the emulated DRV-11J link instead; with --puma the puma cases judge the server's wrist
    side, the suite playing Cougar."""
    console = make_console()
    select = (*select, *cases_of_clauses(clauses, cougar=cougar is not None))
    try:
        select_set = PatternSet.of(select, "--select")
        skip_set = PatternSet.of(skip, "--skip")
        known_set = PatternSet.of(known_failing, "--known-failing")
        address = str(parse_address(host)) if host else ""
    except (PatternError, AddressError) as exc:
        raise click.UsageError(str(exc)) from None
    if host and server_faults:
        raise click.UsageError("--server-fault applies to the embedded server only (omit HOST)")
    if not host and target_time_scale != 1.0:
        raise click.UsageError(
            "--target-time-scale describes HOST's clock (the embedded server keeps its own)"
        )
    config_faults = None
    if server_faults:
        try:
            config_faults = FaultSet.parse(server_faults)
        except ValueError as exc:
            raise click.UsageError(f"--server-fault: {exc}") from None
    if cougar_faults and cougar is None:
        raise click.UsageError(
            "--cougar-fault switches on a defect of the simulated Cougar: add --cougar sim "
            "(without --cougar the suite checks a manip server)"
        )
    if allow_motion and target_kind != "hardware":
        raise click.UsageError(
            "--allow-motion applies to --target hardware (the simulated arm always gets the motion cases)"
        )
    target: CougarTarget | None = None
    if cougar is not None:
        if host or server_faults:
            raise click.UsageError("--cougar checks a Cougar: give no HOST and no --server-fault")
        try:
            target = CougarTarget.parse(cougar, cougar_faults)
        except ValueError as exc:
            raise click.UsageError(f"--cougar: {exc}") from None
        address = "" if target.embedded else target.url
        for name, why in _NOT_WITH_COUGAR.items():
            if given(name):
                raise click.UsageError(f"--{name.replace('_', '-')} {why}, not with --cougar")
    puma_target: PumaTarget | None = None
    if puma:
        if cougar is not None:
            raise click.UsageError("--puma judges a Puma server, --cougar a Cougar: not both")
        if record is not None:
            raise click.UsageError("--record records Chaos connections of a server run, not with --puma")
        if not host and (given("wrist_listen") or given("wrist_wait")):
            raise click.UsageError(
                "--wrist-listen and --wrist-wait are for --puma HOST (the embedded server's wrist is wired "
                "to the judging Cougar by the suite)"
            )
        try:
            puma_target = PumaTarget(
                host=address or None,
                wrist_listen=wrist_listen,
                wrist_wait=wrist_wait,
                faults=server_faults,
                virtual=time_mode != "real",
            )
        except ValueError as exc:
            raise click.UsageError(f"--puma: {exc}") from None
    elif given("wrist_listen") or given("wrist_wait"):
        raise click.UsageError("--wrist-listen and --wrist-wait apply to --puma")
    _check_world(world, world_timeout, host=host, cougar=cougar)
    if record is not None and repeat > 1:
        raise click.UsageError("--record records one run: not with --repeat")
    simulated = not host and target is None
    if time_mode == "virtual" and not simulated:
        raise click.UsageError(
            "--time virtual needs the embedded reference server (no HOST, no --cougar): "
            "another target keeps its own clock"
        )
    virtual = simulated and time_mode != "real"
    if virtual and broken_after is None:
        # In virtual time silence costs only the servo ticks simulated meanwhile: server.ncp.broken runs,
        # against a server whose timer is short enough to keep the run fast (and above the 3 s the
        # other NCP cases stay quiet).
        broken_after = VIRTUAL_BROKEN_AFTER
    check_output_paths(
        record=record, json=json_path, junit=junit_path, html=html_path, markdown=markdown_path
    )
    if seed is None:
        seed = int.from_bytes(os.urandom(4), "big")
    if puma_target is not None:
        cases = puma_cases(all_cases())
    else:
        cases = cougar_cases(all_cases(), cougar=target is not None)
    check_selection(select_set, skip_set, cases, cougar=target is not None)
    options = RunOptions(
        target="hardware" if target_kind == "hardware" else "sim",
        allow_motion=allow_motion,
        strict=strict,
        reply_timeout=reply_timeout,
        deadline_scale=deadline_scale,
        time_scale=target_time_scale,
        max_examples=max_examples,
        address=address,
        broken_after=broken_after,
    )
    extra: list[str] = []
    if broken_after is not None:
        extra += ["--broken-after", f"{broken_after:g}"]
    if strict:
        extra.append("--strict")
    if max_examples != 25:
        extra += ["--max-examples", str(max_examples)]
    if target_time_scale != 1.0:
        extra += ["--target-time-scale", f"{target_time_scale:g}"]
    if target_kind == "hardware":
        extra += ["--target", "hardware"] + (["--allow-motion"] if allow_motion else [])
    for fault in server_faults:
        extra += ["--server-fault", fault]
    if simulated and not virtual:
        extra += ["--time", "real"]
    if world is not None:
        extra += ["--world", world]
    config = RunConfig(
        address=address,
        options=options,
        seed=seed,
        select=select_set,
        skip=skip_set,
        known_failing=known_set,
        embedded=not host if target is None else target.embedded,
        virtual_time=virtual,
        reproduce_options=extra,
        command=shlex.join(["manip-conform", *sys.argv[1:]]),
    )
    if target is not None:
        config.reproduce_prefix = target.reproduce_prefix()
        config.liveness_check = liveness_check
    if puma_target is not None:
        config.reproduce_prefix = puma_target.reproduce_prefix()
    console.print(f"manip-conform: seed [bold]{seed}[/] (rerun with --seed {seed})")
    if repeat > 1:
        report, code = _repeat(
            config,
            cases,
            config_faults,
            console,
            quiet,
            target or puma_target,
            repeat,
            _world_of(world, world_timeout),
        )
    else:
        holder: dict[str, Runner] = {}
        code = _execute(
            config,
            cases,
            config_faults,
            holder,
            console,
            quiet,
            cougar=target or puma_target,
            record=record,
            world=_world_of(world, world_timeout),
        )
        report = holder["runner"].report if "runner" in holder else None
    if report is not None:
        if code == ExitCode.INTERNAL and not report.interrupted and not report.internal_error:
            report.internal_error = "internal error"
        if json_path is not None:
            write_json(report, json_path)
        if junit_path is not None:
            write_junit(report, junit_path)
        write_documents(report, html_path, markdown_path)
        _summary(console, report, quiet)
        code = int(report.exit_code) if code is None else code
    sys.exit(int(code) if code is not None else int(ExitCode.INTERNAL))


def _repeat(
    config: RunConfig,
    cases: Sequence[Case],
    faults: Any,
    console: Console,
    quiet: bool,
    cougar: CougarTarget | PumaTarget | None,
    runs: int,
    world: WorldSpec | None = None,
) -> tuple[RunReport | None, int | None]:
    """``--repeat``: the selection with ``runs`` seeds, then the first seed again; the first run's report
    carries what changed between them (:mod:`manip.conformance.suite.stability`)."""
    seeds = repeat_seeds(config.seed, runs)
    reports: list[RunReport] = []
    worst: int | None = None
    for number, seed in enumerate([*seeds, seeds[0]], start=1):
        holder: dict[str, Runner] = {}
        run_config = replace(config, seed=seed, options=replace(config.options))
        code = _execute(run_config, cases, faults, holder, console, True, cougar=cougar, world=world)
        if "runner" not in holder:
            return None, code
        report = holder["runner"].report
        reports.append(report)
        if code is not None or report.interrupted:
            return reports[0], code
        again = " (its seed again)" if number == len(seeds) + 1 else ""
        console.print(
            f"run {number}/{len(seeds) + 1}{again}: {report.verdict}, {_counts_text(report)}"
            f" in {report.duration:.1f} s; seed {seed}",
            markup=False,
        )
        worst = max(worst or 0, int(report.exit_code))
    first = reports[0]
    first.unstable = instability(reports, compare_packets=config.virtual_time)
    if not first.unstable and worst and worst > int(first.exit_code):
        first.problems.append(f"a repeated run was {ExitCode(worst).name.lower().replace('_', '-')}")
    if not quiet:
        console.print(f"{len(reports)} runs, {len(first.unstable)} stability problem(s)", markup=False)
    return first, None


@dataclass(frozen=True)
class WorldSpec:
    """``--world`` and ``--world-timeout`` as given."""

    spec: str
    timeout: float


def _world_of(world: str | None, timeout: float | None) -> WorldSpec | None:
    if world is None:
        return None
    default = PROMPT_TIMEOUT if world == "prompt" else DEFAULT_ANSWER_TIMEOUT
    return WorldSpec(world, default if timeout is None else timeout)


def _check_world(world: str | None, timeout: float | None, *, host: str | None, cougar: str | None) -> None:
    """Usage errors of ``--world``: it is HOST's world, and ``prompt`` needs a terminal."""
    if world is None:
        if timeout is not None:
            raise click.UsageError("--world-timeout applies to --world")
        return
    if cougar is not None:
        raise click.UsageError("--world arranges a server's world: not with --cougar")
    if not host:
        raise click.UsageError(
            "--world is HOST's world: the embedded server (no HOST) has its own, in-process"
        )
    if world == "prompt" and (problem := check_terminal()) is not None:
        raise click.UsageError(problem)
    if not world.strip():
        raise click.UsageError("--world names nothing: give tcp://HOST:PORT, a command line or prompt")


def _counts_text(report: RunReport) -> str:
    return ", ".join(f"{v} {k}" for k, v in report.counts().items() if v) or "no cases"


def check_selection(
    select: PatternSet,
    skip: PatternSet,
    cases: Sequence[Case],
    *,
    cougar: bool = False,
    hint: str = " (manip-conform cases lists every case)",
) -> None:
    """A usage error when a ``--select`` pattern matches none of ``cases``, or when ``--select`` and
    ``--skip`` together leave no case: a run of nothing would pass, and say nothing of the typo."""
    ids = sorted(c.id for c in cases)
    for pattern in select.patterns:
        if any(match_id(pattern.text, case_id) for case_id in ids):
            continue
        where = "" if pattern.source == "--select" else f" ({pattern.source})"
        message = f"--select {pattern.text!r}{where} matches no case"
        others = [c.id for c in all_cases() if c.id not in ids and match_id(pattern.text, c.id)]
        if others:
            mode = "--cougar" if not cougar else "a server run (without --cougar)"
            if others[0].startswith("client."):
                mode = "manip-conform client"
            message += f" of this run: it names {len(others)} case(s) of {mode}, such as {others[0]}"
        elif close := close_case_ids(pattern.text, ids):
            message += f"; close matches: {', '.join(close)}"
        else:
            areas = sorted({case_id.split(".")[0] + ".*" for case_id in ids})
            message += f"; the case ids are under {', '.join(areas)}"
        raise click.UsageError(message + hint)
    if any((not select or select.matches(i)) and not skip.matches(i) for i in ids):
        return
    options = [f"--select {p.text}" for p in select.patterns] + [f"--skip {p.text}" for p in skip.patterns]
    verb = "leave" if len(options) > 1 else "leaves"
    raise click.UsageError(f"{' '.join(options)} {verb} no case to run")


def cases_of_clauses(clauses: Sequence[str], *, cougar: bool = False) -> list[str]:
    """The ids of the cases (of a Cougar run, or of a server run) that check any of ``clauses``; a usage
    error names an id the spec does not have, with close matches, or a clause no case checks."""
    cases = cougar_cases(all_cases(), cougar=cougar)
    ids: list[str] = []
    for clause in clauses:
        try:
            SPEC.clause(clause)
        except UnknownClauseError as exc:
            raise click.UsageError(f"--clause: {exc}") from None
        checking = [c.id for c in cases if clause in c.clauses]
        if not checking:
            run = "a Cougar run" if cougar else "a server run"
            raise click.UsageError(
                f"--clause {clause}: no case of {run} checks it (manip-conform coverage shows which do)"
            )
        ids += checking
    return ids


def close_case_ids(pattern: str, ids: Sequence[str], limit: int = 3) -> list[str]:
    """Case ids (or the areas above them: ``server.reply``) that look like ``pattern``, its wildcards
    left out, the closest first."""
    names = set(ids)
    for case_id in ids:
        parts = case_id.split(".")
        names.update(".".join(parts[:n]) for n in range(1, len(parts)))
    stem = ".".join(p for p in pattern.split(".") if not any(ch in p for ch in "*?["))
    close = difflib.get_close_matches(stem or pattern, sorted(names), n=limit, cutoff=0.6)
    return close


def _execute(
    config: RunConfig,
    cases: Sequence[Case],
    faults: Any,
    holder: dict[str, Runner],
    console: Console,
    quiet: bool,
    cougar: CougarTarget | PumaTarget | None = None,
    record: Path | None = None,
    world: WorldSpec | None = None,
) -> int | None:
    """Run; None means "use the report's exit code"."""
    try:
        virtual_clock.run(
            _run_async(config, cases, faults, holder, console, quiet, cougar, record, world),
            virtual=config.virtual_time,
        )
    except WorldError as exc:
        console.print(f"[bold red]world unusable[/]: {escape(str(exc))}")
        return int(ExitCode.UNREACHABLE)
    except PumaUnreachableError as exc:
        console.print(f"[bold red]target unreachable[/]: {escape(str(exc))}")
        return int(ExitCode.UNREACHABLE)
    except KeyboardInterrupt:
        if "runner" in holder:
            holder["runner"].report.interrupted = True
            problems = holder["runner"].report.problems
            if not any("interrupted" in p for p in problems):
                problems.append("the run was interrupted; this report is partial")
        console.print("[bold]interrupted[/]: the report is partial")
        return int(ExitCode.INTERNAL)
    except Exception as exc:  # an internal error of the suite: keep what was done
        text = traceback.format_exc()
        console.print(f"[bold magenta]internal error[/]: {type(exc).__name__}: {escape(str(exc))}")
        if "runner" in holder:
            holder["runner"].report.internal_error = text
        else:
            console.print(text, markup=False)
        return int(ExitCode.INTERNAL)
    return None


async def _run_async(
    config: RunConfig,
    cases: Sequence[Case],
    faults: Any,
    holder: dict[str, Runner],
    console: Console,
    quiet: bool,
    cougar: CougarTarget | PumaTarget | None,
    record: Path | None,
    world: WorldSpec | None,
) -> None:
    # The recording starts on the run's loop, so a simulated run records on its virtual clock.
    how = "manip-conform run (client side)"
    with recording(record, how=how, seed=config.seed, virtual=config.virtual_time) as wrap:
        config.wrap_link = wrap
        await _run_target(config, cases, faults, holder, console, quiet, cougar, world)


@contextlib.asynccontextmanager
async def _opened_world(config: RunConfig, world: WorldSpec | None, console: Console) -> AsyncIterator[None]:
    """HOST's world (``--world``) for the block, as the run's (nothing without one)."""
    if world is None:
        yield
        return
    async with open_world(world.spec, answer_timeout=world.timeout) as opened:
        config.world = opened
        console.print(f"world: {opened.description}", markup=False)
        yield


async def _run_target(
    config: RunConfig,
    cases: Sequence[Case],
    faults: Any,
    holder: dict[str, Runner],
    console: Console,
    quiet: bool,
    cougar: CougarTarget | PumaTarget | None,
    world: WorldSpec | None = None,
) -> None:
    if isinstance(cougar, PumaTarget):  # --puma: the suite plays Cougar for the Puma
        await _run_puma(config, cases, holder, console, quiet, cougar, world)
        return
    if cougar is not None:  # --cougar: the Cougar target (embedded or not)
        async with cougar.running() as address:
            config.address = address
            config.options = _with_address(config.options, address)
            if cougar.embedded:
                console.print(f"embedded simulated Cougar at {address}", markup=False)
            await _run_with(config, cases, holder, console, quiet)
        return
    if not config.embedded:
        async with _opened_world(config, world, console):
            await _run_with(config, cases, holder, console, quiet)
        return
    server_config = ServerConfig() if faults is None else ServerConfig(faults=faults)
    # The embedded robot has the simulated Cougar wrist, so the wrist opcodes are checked too.
    if config.virtual_time:
        async with simulated_environment(
            server_config, seed=config.seed, wrist=True, broken_after=config.options.broken_after
        ) as environment:
            address = environment.address
            config.address = address
            config.world = environment.world
            config.options = replace(config.options, address=address, embedded=True)
            console.print("embedded reference server in virtual time (with the simulated Cougar wrist)")
            await _run_with(config, cases, holder, console, quiet)
        return
    embedded = EmbeddedServer(server_config, wrist=True, broken_after=config.options.broken_after)
    with embedded as address:
        config.address = address
        config.world = embedded.environment.world if embedded.environment is not None else None
        config.options = replace(config.options, address=address, embedded=True)
        console.print(
            f"embedded reference server at {address} (with the simulated Cougar wrist)", markup=False
        )
        await _run_with(config, cases, holder, console, quiet)


async def _run_puma(
    config: RunConfig,
    cases: Sequence[Case],
    holder: dict[str, Runner],
    console: Console,
    quiet: bool,
    puma: PumaTarget,
    world: WorldSpec | None = None,
) -> None:
    if puma.host is not None:
        console.print(
            f"judging Cougar listening on {puma.wrist_listen}: waiting up to {puma.wrist_wait:g} s for the "
            f"Puma's wrist link (manip-server --cougar {puma.wrist_listen})",
            markup=False,
        )
    async with puma.running_with_world(config.seed) as (address, own_world):
        config.address = address
        config.world = own_world or config.world
        config.options = _with_address(config.options, address)
        if puma.embedded:
            how = "in virtual time" if config.virtual_time else f"at {address}"
            console.print(
                f"embedded reference server {how}, its wrist played by the judging Cougar", markup=False
            )
        else:
            console.print(f"the Puma's wrist link is up; judging {address}", markup=False)
        async with _opened_world(config, world, console):  # HOST's, once it is up
            await _run_with(config, cases, holder, console, quiet)


def _with_address(options: RunOptions, address: str) -> RunOptions:
    return replace(options, address=address)


async def _run_with(
    config: RunConfig, cases: Sequence[Case], holder: dict[str, Runner], console: Console, quiet: bool
) -> None:
    progress = progress_bar(
        console, quiet or isinstance(config.world, PromptWorld)
    )  # it would hide the questions
    task_id = progress.add_task("conformance", total=0)

    def started(selected: list[Case]) -> None:
        progress.update(task_id, total=len(selected))

    def case_started(item: Case) -> None:
        progress.update(task_id, description=item.id)

    def case_finished(result: CaseResult) -> None:
        # One line as it happens; the details come after the run, below the broken clauses (_summary).
        progress.advance(task_id)
        if _shown(result, quiet):
            _headline(progress.console, result)

    def liveness(check: LivenessCheck) -> None:
        if not check.alive:
            progress.console.print(
                f"[bold red]target not alive[/] ({escape(check.when)}): {escape(check.detail)}"
            )

    runner = Runner(config, cases, RunEvents(started, case_started, case_finished, liveness))
    holder["runner"] = runner
    with progress:
        await runner.run()


def _shown(result: CaseResult, quiet: bool) -> bool:
    return result.outcome in ("fail", "error", "fixed") or (result.outcome == "warn" and not quiet)


def _headline(console: Console, result: CaseResult) -> None:
    style = _STYLE[result.outcome]
    clauses = sorted({v.clause for v in result.violations if v.clause})
    broke = f" [{', '.join(clauses)}]" if clauses else ""
    head = f"{escape(result.id)} ({result.duration:.2f} s){escape(broke)}"
    console.print(f"[{style}]{result.outcome.upper():>10}[/] {head}")


def _details(console: Console, report: RunReport, quiet: bool) -> None:
    """Each failing (or warning, fixed, erring) case in full: what was expected, what came, the bytes,
    the command that reproduces it."""
    for result in report.results:
        if not _shown(result, quiet):
            continue
        _headline(console, result)
        body = failure_text(result) if result.outcome != "error" else result.traceback.rstrip()
        if result.outcome == "fixed":
            body = "listed in --known-failing but passed: remove the entry"
        if body:
            console.print(body, markup=False, highlight=False)


def _summary(console: Console, report: RunReport, quiet: bool = False) -> None:
    """After the run: the broken clauses (one line each), then every failure in full, then problems and
    the verdict."""
    counts = report.counts()
    parts = [f"[{_STYLE[k]}]{v} {k}[/]" for k, v in counts.items() if v]
    print_by_clause(console, report)
    _details(console, report, quiet)
    for problem in report.problems:
        console.print(f"[bold red]problem[/]: {escape(problem)}")
    for problem in report.unstable:
        console.print(f"[bold magenta]unstable[/]: {escape(problem)}")
    verdict_style = "bold green" if report.exit_code == ExitCode.CONFORMANT else "bold red"
    shown = ", ".join(parts) or "no cases"
    unjudged = report.not_judged_hints()
    console.print(
        f"[{verdict_style}]{report.verdict}[/] (exit {int(report.exit_code)}): {shown}"
        f" in {report.duration:.1f} s; seed {report.seed}"
        + ("; virtual time" if report.time == "virtual" else "")
        + (f"; {len(unjudged)} MUST clause(s) not judged on this target" if unjudged else "")
    )
    if unjudged:
        listed = ", ".join(f"{clause} ({hint})" for clause, hint in unjudged.items())
        console.print(
            f"[{_STYLE['not-judged']}]not judged[/]: {escape(listed)}; what would judge each is in brackets"
        )
        if "--world" in unjudged.values():
            console.print(f"--world: {escape(WITHOUT_WORLD)}")
    slow = [r for r in report.results if r.deadline and r.duration > 0.8 * r.deadline]
    for r in slow:
        console.print(
            f"[yellow]slow[/]: {escape(r.id)} took {r.duration:.2f} s of its {r.deadline:g} s deadline"
        )


# ----------------------------------------------------------------------------------------------- cases


@main.command("cases", epilog=epilog("manip-conform cases, report"))
@click.option("--format", "fmt", type=click.Choice(["table", "json"]), default="table", show_default=True)
@click.option("--select", "select", multiple=True, metavar="PATTERN", help="Only cases matching PATTERN.")
def cases_command(fmt: str, select: tuple[str, ...]) -> None:
    """List every case: id, clauses, level, kind, hazard."""
    try:
        patterns = PatternSet.of(select, "--select")
    except PatternError as exc:
        raise click.UsageError(str(exc)) from None
    check_selection(patterns, PatternSet(), all_cases(), hint="")
    items = [c for c in all_cases() if not patterns or patterns.matches(c.id)]
    if fmt == "json":
        data = [
            {
                "id": c.id,
                "clauses": list(c.clauses),
                "level": c.level,
                "kind": c.technique,
                "target": c.target,
                "hazard": c.hazard,
                "deadline": c.deadline,
                "summary": c.summary,
            }
            for c in items
        ]
        click.echo(json.dumps(data, indent=2))
        return
    table = Table(title=f"{len(items)} cases", show_lines=False)
    for column in ("id", "level", "kind", "hazard", "clauses"):
        table.add_column(column)
    for c in items:
        table.add_row(c.id, c.level, c.technique, c.hazard, " ".join(c.clauses))
    make_console(min_width=TABLE_WIDTH).print(table)


# ----------------------------------------------------------------------------------------------- coverage


@main.command("coverage", epilog=epilog("manip-conform coverage"))
@click.option("--format", "fmt", type=click.Choice(["table", "json"]), default="table", show_default=True)
@click.option(
    "--party",
    "parties",
    multiple=True,
    type=click.Choice(["server", "client", "both", "cougar", "puma", "link"]),
    help=f"Parties whose MUST clauses must be covered (default: {', '.join(sorted(DEFAULT_PARTIES))}).",
)
def coverage_command(fmt: str, parties: tuple[str, ...]) -> None:
    """Map every clause to the cases that check it; exit 1 if a MUST clause in scope has none."""
    rows = coverage(all_cases(), parties or DEFAULT_PARTIES)
    missing = gaps(rows)
    if fmt == "json":
        data = {
            "parties": sorted(parties or DEFAULT_PARTIES),
            "clauses": [
                {
                    "clause": r.clause,
                    "level": r.level,
                    "party": r.party,
                    "in_scope": r.in_scope,
                    "cases": list(r.cases),
                }
                for r in rows
            ],
            "uncovered_must": [r.clause for r in missing],
        }
        click.echo(json.dumps(data, indent=2))
    else:
        table = Table(title="clause coverage")
        for column in ("clause", "level", "party", "cases"):
            table.add_column(column)
        for r in rows:
            cases_text = ", ".join(r.cases) if r.cases else ("[bold red]NONE[/]" if r.gap else "[dim]-[/]")
            table.add_row(r.clause, r.level, r.party + ("" if r.in_scope else " (out of scope)"), cases_text)
        console = make_console(min_width=TABLE_WIDTH)
        console.print(table)
        covered = sum(1 for r in rows if r.cases)
        console.print(
            f"{covered} of {len(rows)} clauses have a case; {len(missing)} MUST clause(s) in scope have none"
        )
    sys.exit(1 if missing else 0)


# ----------------------------------------------------------------------------------------------- report


@main.command("report", epilog=epilog("manip-conform cases, report"))
@click.argument(
    "report_file", metavar="REPORT.json", type=click.Path(exists=True, dir_okay=False, path_type=Path)
)
@document_options
def report_command(report_file: Path, html_path: Path | None, markdown_path: Path | None) -> None:
    """Render a saved JSON report (of run, verify or replay --json) as a one-file HTML report and/or a
    Markdown summary.  Exit 0 when written, whatever the run's verdict; 2 on a usage error or a file
    that is not a manip-conform JSON report."""
    if html_path is None and markdown_path is None:
        raise click.UsageError("give --html FILE, --markdown FILE or both")
    check_output_paths(html=html_path, markdown=markdown_path)
    try:
        render_saved(report_file, html_path, markdown_path)
    except ReportError as exc:
        raise click.UsageError(str(exc)) from None


main.add_command(replay_command)
main.add_command(verify_command)
main.add_command(fuzz_command)
main.add_command(client_command)

if __name__ == "__main__":  # pragma: no cover
    main()
