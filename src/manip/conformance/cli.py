"""``manip-conform``: run the conformance suite, list its cases, map clause coverage.

Commands::

    manip-conform run [HOST] [options]     run the suite (no HOST: against the embedded reference server)
    manip-conform cases [--format table|json] [--select P]...
    manip-conform coverage [--format table|json] [--party P]...
    manip-conform report REPORT.json [--html FILE] [--markdown FILE]

Exit codes of ``run`` (documented in ``--help``):

    0  conformant: no MUST failure (nor SHOULD failure with --strict), no stale known-failing entry
    1  non-conformant: a failure, a stale known-failing entry, or the target died or broke the exchange
    2  usage error (bad option, pattern, address or pattern file; a --select matching no case; an
       option of a target not chosen; a report or capture path that cannot be written)
    3  target unreachable: nothing it sent (not even an initial RESPONSE) reached the run
    4  interrupted, an internal error of the suite, or a verdict that changed with the seed (``--repeat``;
       a partial report is still written)

``coverage`` exits 1 when a MUST clause in scope has no case.  The group leaves room for more
subcommands (``replay``, ``verify``) added by other modules: they register on :data:`main`.
"""

from __future__ import annotations

import json
import os
import shlex
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal, TypeVar

import click
from rich.console import Console

from manip.arm.units import LENGTH_UNITS, LengthUnit
from manip.commandline import FiniteFloat, broken_after_option, configure_logging, version_option
from manip.conformance.cli_options import (
    cases_of_clauses,
    check_output_paths,
    check_selection,
    document_options,
    given,
    known_failing_option,
    report_options,
    select_option,
    skip_option,
    strict_option,
)
from manip.conformance.client.cli import client_command
from manip.conformance.cougar.target import CougarTarget, cougar_cases, liveness_check
from manip.conformance.diff.cli import diff_command
from manip.conformance.fuzz.cli import fuzz_command
from manip.conformance.output.console import make_console, print_table
from manip.conformance.output.coverage import DEFAULT_PARTIES, coverage, gaps
from manip.conformance.output.documents import ReportError, ReportPaths, render_saved, write_reports
from manip.conformance.output.run_console import summary
from manip.conformance.puma.target import (
    DEFAULT_WRIST_LISTEN,
    DEFAULT_WRIST_WAIT,
    PumaTarget,
    puma_cases,
)
from manip.conformance.replay.cli import replay_command, verify_command
from manip.conformance.suite.case import all_cases
from manip.conformance.suite.context import DEFAULT_REPLY_TIMEOUT, RunOptions
from manip.conformance.suite.results import ExitCode, RunReport
from manip.conformance.suite.runner import RunConfig
from manip.conformance.suite.selection import PatternError, PatternSet
from manip.conformance.suite.world_prompt import check_terminal
from manip.conformance.targets import Job, execute, repeat_run, world_of
from manip.cougar.memory_map import MemoryMapError
from manip.exit_status import epilog
from manip.links import AddressError, parse_address
from manip.reference_server import FaultSet
from manip.reference_server.session import PROFILES

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
"""On a terminal, the ``cases`` and ``coverage`` tables are laid out at least this wide."""
VIRTUAL_BROKEN_AFTER = 10.0
"""The embedded server's broken-connection timer in a virtual-time run without --broken-after (s)."""


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
    "robot",
    type=click.Choice(["sim", "hardware"]),
    default="sim",
    show_default=True,
    help="hardware: motion and power cases are left out unless --allow-motion.",
)
@click.option("--allow-motion", is_flag=True, help="With --target hardware, run motion and power cases too.")
@_number_option(
    "--reply-timeout", FiniteFloat(0.01), DEFAULT_REPLY_TIMEOUT, "Seconds to wait for each reply."
)
@_number_option(
    "--deadline-scale", FiniteFloat(0.01), 1.0, "Multiply every case deadline (slow links, real arms)."
)
@_number_option(
    "--target-time-scale",
    FiniteFloat(min=0.01),
    1.0,
    "HOST's arm runs this many times faster than real time (a simulated server started with --time-scale):"
    " its 16 ms servo cycle is judged at that rate (erratum server-time-scale).",
)
@broken_after_option(
    "The target's broken-connection timer (90 s by default, the ITS Chaos NCP's: the 1985 guide "
    "gives none; erratum ncp-timers): server.ncp.broken goes silent "
    "that long and checks the connection was given up.  Without it that case is skipped, except against "
    "the embedded server in virtual time, whose timer is then 10 s (silence costs little there).  With the "
    "embedded server, the server gets this timer too (below 5 s the other NCP cases, which keep quiet "
    "for up to 3 s on purpose, may lose their connections)."
)
@report_options
@click.option(
    "--length-unit",
    type=click.Choice([*LENGTH_UNITS, "auto"]),
    default="mm",
    show_default=True,
    help="The unit of the target's lengths, which the 1985 guide does not give (erratum units): every "
    "Cartesian move the suite makes (straight-line, incremental, move to a transform) and every position "
    "tolerance is sized in it, and with --cougar a Cougar's frame vector and centre of gravity.  A move "
    "refused as out of reach is not judged, and says to try another.  auto (not with --cougar): learned "
    "before the cases from the height of the target's ready pose (one solve backwards; a PUMA 600's, else "
    "mm).",
)
@click.option(
    "--server-profile",
    type=click.Choice(PROFILES),
    default="manip",
    show_default=True,
    help="Embedded server only: run the reference server as manip documents it, or as a server written "
    "from the 1985 guide alone (guide: no extension opcodes, lengths in inches, asynchronous responses "
    "in the guide's 6-byte layout; manip-server --profile guide).",
)
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
    "--cougar-reading",
    "cougar_readings",
    multiple=True,
    metavar="NAME",
    help="With --cougar sim: the simulated Cougar takes another reading of the 1985 guide, one the suite "
    "must accept (see manip-cougar --help).",
)
@click.option(
    "--memory-map",
    "memory_map",
    type=click.Path(path_type=Path, dir_okay=False),
    default=None,
    metavar="FILE",
    help="With --cougar: the Cougar's memory map (TOML, docs/drv11j.md), for the cases that read or write "
    "its memory; without one they are not judged (--cougar sim declares its own).",
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
    type=FiniteFloat(min=0.1),
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
    type=FiniteFloat(min=0.1),
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
    robot: str,
    allow_motion: bool,
    reply_timeout: float,
    deadline_scale: float,
    target_time_scale: float,
    broken_after: float | None,
    reports: ReportPaths,
    length_unit: LengthUnit | Literal["auto"],
    server_profile: str,
    server_faults: tuple[str, ...],
    cougar: str | None,
    cougar_faults: tuple[str, ...],
    cougar_readings: tuple[str, ...],
    memory_map: Path | None,
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
        if host:
            parse_address(host)  # checked; kept as given, so a reproduce line names it as the user did
        address = host or ""
    except (PatternError, AddressError) as exc:
        raise click.UsageError(str(exc)) from None
    config_faults = _check_server_options(
        host, server_faults, target_time_scale, cougar, cougar_faults, allow_motion, robot
    )
    _check_profile(server_profile, host=host, cougar=cougar)
    _check_length_unit(length_unit, cougar=cougar)
    target = _cougar_target(
        cougar, (cougar_faults, cougar_readings), memory_map, host=host, server_faults=server_faults
    )
    if target is not None:
        address = "" if target.embedded else target.url
    puma_target = _puma_target(
        puma, host=address or None, cougar=cougar, record=record, wrist=(wrist_listen, wrist_wait),
        faults=server_faults, virtual=time_mode != "real",
    )  # fmt: skip
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
    check_output_paths(record=record, **reports.paths)
    if seed is None:
        seed = int.from_bytes(os.urandom(4), "big")
    if puma_target is not None:
        cases = puma_cases(all_cases())
    else:
        cases = cougar_cases(all_cases(), cougar=target is not None)
    check_selection(select_set, skip_set, cases, cougar=target is not None)
    options = RunOptions(
        robot="hardware" if robot == "hardware" else "sim",
        allow_motion=allow_motion,
        strict=strict,
        reply_timeout=reply_timeout,
        deadline_scale=deadline_scale,
        time_scale=target_time_scale,
        max_examples=max_examples,
        address=address,
        embedded=not host if target is None else target.embedded,
        broken_after=broken_after,
        cougar_map=target.declared_map() if target is not None else None,
        length_unit="mm" if length_unit == "auto" else length_unit,
        learn_length_unit=length_unit == "auto",
    )
    config = RunConfig(
        options=options,
        seed=seed,
        select=select_set,
        skip=skip_set,
        known_failing=known_set,
        virtual_time=virtual,
        reproduce_options=_reproduce_options(
            options, server_faults, simulated=simulated, virtual=virtual, world=world, profile=server_profile
        ),
        command=shlex.join(["manip-conform", *sys.argv[1:]]),
    )
    if target is not None:
        config.reproduce_prefix = target.reproduce_prefix()
        config.liveness_check = liveness_check
    if puma_target is not None:
        config.reproduce_prefix = puma_target.reproduce_prefix()
    console.print(f"manip-conform: seed [bold]{seed}[/] (rerun with --seed {seed})")
    console.print(
        "lengths: learned from the target's ready pose (--length-unit auto; the 1985 guide gives no unit)"
        if length_unit == "auto"
        else f"lengths taken in {length_unit} (--length-unit; the 1985 guide gives no unit: erratum units)",
        markup=False,
    )
    job = Job(
        config, cases, console, quiet, faults=config_faults, target=target or puma_target,
        world=world_of(world, world_timeout), server_profile=server_profile,
    )  # fmt: skip
    if repeat > 1:
        report, code = repeat_run(job, repeat)
    else:
        code = execute(job, record)
        report = job.report
    sys.exit(_finish(report, code, console, quiet, reports))


def _check_profile(server_profile: str, *, host: str | None, cougar: str | None) -> None:
    """A server profile other than manip's own chooses how the embedded server behaves: no other target."""
    if server_profile != "manip" and (host or cougar is not None):
        raise click.UsageError(
            "--server-profile applies to the embedded server only (omit HOST and --cougar)"
        )


def _check_length_unit(length_unit: str, *, cougar: str | None) -> None:
    """``--length-unit auto`` learns the unit from a Chaos target's ready pose: a Cougar has none."""
    if length_unit == "auto" and cougar is not None:
        raise click.UsageError(
            "--length-unit auto learns the unit from a server's ready pose: with --cougar name it"
        )


def _check_server_options(
    host: str | None,
    server_faults: tuple[str, ...],
    target_time_scale: float,
    cougar: str | None,
    cougar_faults: tuple[str, ...],
    allow_motion: bool,
    robot: str,
) -> FaultSet | None:
    """Usage errors of the options that describe the server (or its absence); the embedded server's
    fault set, if any."""
    if host and server_faults:
        raise click.UsageError("--server-fault applies to the embedded server only (omit HOST)")
    if not host and target_time_scale != 1.0:
        raise click.UsageError(
            "--target-time-scale describes HOST's clock (the embedded server keeps its own)"
        )
    if cougar_faults and cougar is None:
        raise click.UsageError(
            "--cougar-fault switches on a defect of the simulated Cougar: add --cougar sim "
            "(without --cougar the suite checks a manip server)"
        )
    if allow_motion and robot != "hardware":
        raise click.UsageError(
            "--allow-motion applies to --target hardware (the simulated arm always gets the motion cases)"
        )
    if not server_faults:
        return None
    try:
        return FaultSet.parse(server_faults)
    except ValueError as exc:
        raise click.UsageError(f"--server-fault: {exc}") from None


def _cougar_target(
    cougar: str | None,
    switches: tuple[tuple[str, ...], tuple[str, ...]],
    memory_map: Path | None,
    *,
    host: str | None,
    server_faults: tuple[str, ...],
) -> CougarTarget | None:
    """``--cougar``: the Cougar to judge instead of a server (its faults and readings, its memory map),
    and the options that cannot go with it."""
    if cougar is None:
        for option in ("cougar_readings", "memory_map"):
            if given(option):
                name = option.replace("_", "-").removesuffix("s")
                raise click.UsageError(f"--{name} describes a Cougar: add --cougar")
        return None
    if host or server_faults:
        raise click.UsageError("--cougar checks a Cougar: give no HOST and no --server-fault")
    try:
        target = CougarTarget.parse(cougar, *switches, memory_map=memory_map)
    except MemoryMapError as exc:
        raise click.UsageError(f"--memory-map: {exc}") from None
    except ValueError as exc:
        raise click.UsageError(f"--cougar: {exc}") from None
    for name, why in _NOT_WITH_COUGAR.items():
        if given(name):
            raise click.UsageError(f"--{name.replace('_', '-')} {why}, not with --cougar")
    return target


def _puma_target(
    puma: bool,
    *,
    host: str | None,
    cougar: str | None,
    record: Path | None,
    wrist: tuple[str, float],
    faults: tuple[str, ...],
    virtual: bool,
) -> PumaTarget | None:
    """``--puma``: the Puma whose wrist side the suite judges, playing Cougar at ``wrist`` (where it
    listens, how long it waits); the wrist options without it are an error."""
    if not puma:
        if given("wrist_listen") or given("wrist_wait"):
            raise click.UsageError("--wrist-listen and --wrist-wait apply to --puma")
        return None
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
        return PumaTarget(
            host=host, wrist_listen=wrist[0], wrist_wait=wrist[1], faults=faults, virtual=virtual
        )
    except ValueError as exc:
        raise click.UsageError(f"--puma: {exc}") from None


def _reproduce_options(
    options: RunOptions,
    server_faults: tuple[str, ...],
    *,
    simulated: bool,
    virtual: bool,
    world: str | None,
    profile: str = "manip",
) -> list[str]:
    """The options a case's reproduce line repeats: those that change what the case does or how it is
    judged (not the selection, the reports or the seed, which the line gives itself)."""
    extra: list[str] = []
    if options.broken_after is not None:
        extra += ["--broken-after", f"{options.broken_after:g}"]
    if options.strict:
        extra.append("--strict")
    if options.max_examples != 25:
        extra += ["--max-examples", str(options.max_examples)]
    if options.time_scale != 1.0:
        extra += ["--target-time-scale", f"{options.time_scale:g}"]
    if options.learn_length_unit or options.length_unit != "mm":
        extra += ["--length-unit", "auto" if options.learn_length_unit else options.length_unit]
    if options.robot == "hardware":
        extra += ["--target", "hardware"] + (["--allow-motion"] if options.allow_motion else [])
    if profile != "manip":
        extra += ["--server-profile", profile]
    for fault in server_faults:
        extra += ["--server-fault", fault]
    if simulated and not virtual:
        extra += ["--time", "real"]
    if world is not None:
        extra += ["--world", world]
    return extra


def _finish(
    report: RunReport | None, code: int | None, console: Console, quiet: bool, reports: ReportPaths
) -> int:
    """The reports written, the summary printed; the exit status (``code``, else the report's)."""
    if report is None:
        return int(code) if code is not None else int(ExitCode.INTERNAL)
    if code == ExitCode.INTERNAL and not report.interrupted and not report.internal_error:
        report.internal_error = "internal error"
    report.unwritten.extend(write_reports(report, reports))
    for problem in report.unwritten:  # a report path that cannot be written is a usage error, found late
        click.echo(f"manip-conform: {problem}", err=True)
    learned = report.options.get("length_unit_learned")
    if learned:
        console.print(f"lengths (--length-unit auto): {learned}", markup=False)
    summary(console, report, quiet)
    return int(report.exit_code) if code is None or report.unwritten else int(code)


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


# ----------------------------------------------------------------------------------------------- cases


@main.command("cases", epilog=epilog("manip-conform cases, report"))
@click.option("--format", "fmt", type=click.Choice(["table", "json"]), default="table", show_default=True)
@click.option("--select", "select", multiple=True, metavar="PATTERN", help="Only cases matching PATTERN.")
def cases_command(fmt: str, select: tuple[str, ...]) -> None:
    """List every case: id, clauses, level, kind, hazard, the Puma extension opcodes it uses."""
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
                "extensions": list(c.extensions),
                "deadline": c.deadline,
                "summary": c.summary,
            }
            for c in items
        ]
        click.echo(json.dumps(data, indent=2))
        return
    rows = [
        (c.id, c.level, c.technique, c.hazard, " ".join(c.extensions), " ".join(c.clauses)) for c in items
    ]
    columns = ("id", "level", "kind", "hazard", "extensions", "clauses")
    print_table(make_console(min_width=TABLE_WIDTH), f"{len(items)} cases", columns, rows)


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
        lines = [
            (
                r.clause,
                r.level,
                r.party + ("" if r.in_scope else " (out of scope)"),
                ", ".join(r.cases) if r.cases else ("[bold red]NONE[/]" if r.gap else "[dim]-[/]"),
            )
            for r in rows
        ]
        console = make_console(min_width=TABLE_WIDTH)
        print_table(console, "clause coverage", ("clause", "level", "party", "cases"), lines)
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
def report_command(report_file: Path, reports: ReportPaths) -> None:
    """Render a saved JSON report (of run, client, verify, replay or fuzz --json) as a one-file HTML
    report and/or a Markdown summary.  Exit 0 when written, whatever the run's verdict; 2 on a usage
    error or a file that is not a manip-conform JSON report."""
    if not reports.paths:
        raise click.UsageError("give --html FILE, --markdown FILE or both")
    check_output_paths(**reports.paths)
    try:
        render_saved(report_file, reports.get("html"), reports.get("markdown"))
    except (ReportError, OSError) as exc:  # OSError: manip.outfile.OutputError, naming the path
        raise click.UsageError(str(exc)) from None


main.add_command(replay_command)
main.add_command(verify_command)
main.add_command(fuzz_command)
main.add_command(diff_command)
main.add_command(client_command)

if __name__ == "__main__":  # pragma: no cover
    main()
