"""``manip-conform fuzz [HOST]``: a seeded, bounded fuzz campaign against a server.

Without HOST the target is the reference server, started by the fuzzer on a free loopback port
(``--server-fault`` switches a defect on, ``--link chudp`` fuzzes its CHUDP link, ``--wrist`` gives
it the simulated Cougar wrist).  With HOST any server; ``--launch CMD`` lets the fuzzer start (and
restart after a crash) the server itself and read its log for tracebacks, ``--server-log FILE``
reads the log of a server started elsewhere.
"""

from __future__ import annotations

import asyncio
import os
import shlex
import sys
import time
import traceback
from dataclasses import dataclass
from pathlib import Path

import click
from rich.console import Console
from rich.markup import escape

from manip.commandline import CommandLine, FiniteFloat
from manip.conformance.cli_options import check_output_paths, given, report_options
from manip.conformance.fuzz.campaign import Campaign, CampaignConfig, CampaignEvents
from manip.conformance.fuzz.generators import INPUT_CLASSES, GenOptions
from manip.conformance.fuzz.report import CampaignFacts, CampaignViolation, violation_text
from manip.conformance.fuzz.target import FuzzedServer, LaunchedServer, RemoteServer, reference_server_argv
from manip.conformance.output.console import make_console, progress_bar
from manip.conformance.output.documents import ReportPaths, write_reports
from manip.conformance.suite.context import DEFAULT_CONNECT_TIMEOUT, DEFAULT_REPLY_TIMEOUT, RunOptions
from manip.conformance.suite.results import ExitCode, RunReport
from manip.conformance.suite.selection import match_id
from manip.exit_status import epilog
from manip.links import AddressError, LinkAddress, parse_address
from manip.reference_server import FaultSet

__all__ = ["fuzz_command"]

EXIT_CODES_HELP = epilog("manip-conform fuzz")

_STYLE = {"crash": "bold red", "timeout": "bold red", "traceback": "bold magenta"}


def _numbers(ctx: click.Context, param: click.Parameter, value: str | None) -> tuple[int, ...]:
    if value is None:
        return ()
    try:
        numbers = tuple(int(x) for x in value.replace(" ", "").split(",") if x)
    except ValueError:
        raise click.BadParameter(f"{value!r} is not a list of input numbers (e.g. 12,40)") from None
    if not numbers or any(n < 0 for n in numbers):
        raise click.BadParameter("give input numbers 0 and up, comma separated")
    return numbers


def class_listing() -> str:
    lines = []
    for c in INPUT_CLASSES.values():
        links = "" if len(c.links) == 2 else f" ({', '.join(sorted(c.links))} links only)"
        lines.append(f"{c.id}  [{c.level}, {c.hazard}]{links}")
        lines.append(f"    sends:    {c.sends}")
        lines.append(f"    expected: {c.expected}")
        lines.append(f"    clauses:  {', '.join(c.clauses)}")
    return "\n".join(lines)


@click.command("fuzz", epilog=EXIT_CODES_HELP)
@click.argument("host", required=False)
@click.option(
    "--seed",
    type=click.IntRange(0, 2**63 - 1),
    default=None,
    help="Seed of every input (printed; the same seed sends the same inputs).",
)
@click.option(
    "--inputs", "inputs", type=click.IntRange(1), default=10_000, show_default=True, help="Inputs to send."
)
@click.option(
    "--seconds",
    type=FiniteFloat(min=0.1),
    default=None,
    help="Stop after this long (after the batch under way), whatever --inputs says.",
)
@click.option(
    "--batch",
    type=click.IntRange(1, 1000),
    default=100,
    show_default=True,
    help="Inputs per batch (one connection, then a liveness check).",
)
@click.option(
    "--class",
    "classes",
    multiple=True,
    metavar="PATTERN",
    help="Only input classes matching PATTERN (manip.*, chaos.rfc-*); repeatable (--list-classes).",
)
@click.option(
    "--list-classes",
    is_flag=True,
    help="List the input classes (what each sends, what the spec says the answer must be) and exit.",
)
@click.option(
    "--only",
    callback=_numbers,
    default=None,
    metavar="N[,N...]",
    help="Send only these inputs of the seed's campaign, as one batch (a reproduce line does this).",
)
@click.option(
    "--target",
    "target_kind",
    type=click.Choice(["sim", "hardware"]),
    default="sim",
    show_default=True,
    help="hardware: no motion or power opcode is sent at all unless --allow-motion.",
)
@click.option(
    "--allow-motion", is_flag=True, help="With --target hardware, send motion and power opcodes too."
)
@click.option(
    "--reply-timeout",
    type=FiniteFloat(0.01),
    default=DEFAULT_REPLY_TIMEOUT,
    show_default=True,
    help="Seconds an answer may take (a wait for the arm gets the spec's allowance on top).",
)
@click.option(
    "--connect-timeout",
    type=FiniteFloat(0.01),
    default=DEFAULT_CONNECT_TIMEOUT,
    show_default=True,
    help="Seconds a connection may take to open (a busy robot included).",
)
@click.option(
    "--deadline-scale",
    type=FiniteFloat(0.01),
    default=1.0,
    show_default=True,
    help="Multiply every wait for the arm (slow links, real arms).",
)
@click.option(
    "--server-fault",
    "server_faults",
    multiple=True,
    metavar="NAME[=ARG]",
    help="Without HOST: switch on a fault of the reference server (manip-server --list-faults).",
)
@click.option(
    "--link",
    "link",
    type=click.Choice(["tcp", "chudp"]),
    default="tcp",
    show_default=True,
    help="Without HOST: the reference server's link to fuzz.",
)
@click.option(
    "--wrist",
    is_flag=True,
    help="Without HOST: give the reference server the simulated Cougar wrist (slower: its link runs in "
    "real time).",
)
@click.option(
    "--launch",
    metavar="CMD",
    type=CommandLine(),
    default=None,
    help="With HOST: start the server with CMD, restart it after a crash, read its output for tracebacks.",
)
@click.option(
    "--server-log",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="With HOST: the server's log file; a traceback written to it is a violation.",
)
@click.option(
    "--restart-wait",
    type=FiniteFloat(min=0.0),
    default=0.0,
    show_default=True,
    metavar="SECONDS",
    help="With HOST (no --launch): after a crash, wait this long for the server to come back (to go on, "
    "and to shrink the crash).",
)
@click.option("--no-shrink", is_flag=True, help="Report violations with their whole batch, unshrunk.")
@click.option(
    "--shrink-seconds",
    type=FiniteFloat(min=1.0),
    default=60.0,
    show_default=True,
    help="Most time spent shrinking one violation.",
)
@click.option(
    "--strict", is_flag=True, help="Violations of SHOULD clauses count (without it they are warnings)."
)
@report_options
@click.option("-q", "--quiet", is_flag=True, help="No progress bar; violations and the summary only.")
def fuzz_command(
    host: str | None,
    seed: int | None,
    inputs: int,
    seconds: float | None,
    batch: int,
    classes: tuple[str, ...],
    list_classes: bool,
    only: tuple[int, ...],
    target_kind: str,
    allow_motion: bool,
    reply_timeout: float,
    connect_timeout: float,
    deadline_scale: float,
    server_faults: tuple[str, ...],
    link: str,
    wrist: bool,
    launch: str | None,
    server_log: Path | None,
    restart_wait: float,
    no_shrink: bool,
    shrink_seconds: float,
    strict: bool,
    reports: ReportPaths,
    quiet: bool,
) -> None:
    """Fuzz HOST (tcp://HOST:PORT, unix:///PATH or chudp://HOST:PORT?addr=OCTAL) with inputs made from
    the spec's tables: malformed frames and datagrams, out-of-window and wrong-index Chaos packets,
    RFC floods, every request opcode at every wrong length, reserved-operand and extreme floats,
    pipelines that do not read.  Each answer is judged against the spec; after each batch a new
    connection must be served.  Crashes, hangs, silent drops (no answer where one is due), wrong
    answers and tracebacks are reported with the fewest inputs that cause them and a reproduce line.
    Without HOST the reference server is started on a free loopback port and fuzzed."""
    if list_classes:
        click.echo(class_listing())
        return
    console = make_console()
    _check_options(host, launch, server_log, target_kind, allow_motion, only, server_faults, classes)
    address = _address(host)
    check_output_paths(**reports.paths)
    if seed is None:
        seed = int.from_bytes(os.urandom(4), "big")
    options = RunOptions(
        robot="hardware" if target_kind == "hardware" else "sim",
        allow_motion=allow_motion,
        strict=strict,
        reply_timeout=reply_timeout,
        connect_timeout=connect_timeout,
        deadline_scale=deadline_scale,
        address=host or "",
        embedded=address is None,
    )
    chudp = (address.scheme == "chudp") if address is not None else link == "chudp"
    gen = GenOptions(
        link="datagram" if chudp else "stream",
        hazards=options.allowed_hazards,
        select=classes,
        contact=address.contact if address is not None else "PUMA",
    )
    if not gen.classes():
        raise click.UsageError(
            "--class and --target leave no input class to send on this link (--list-classes)"
        )
    server = _Server(address, link, server_faults, wrist, launch, server_log)
    config = CampaignConfig(
        seed=seed,
        gen=gen,
        inputs=inputs,
        seconds=seconds,
        batch=batch,
        only=only,
        options=options,
        shrink=not no_shrink,
        shrink_seconds=shrink_seconds,
        restart_wait=restart_wait,
        reproduce_prefix=["manip-conform", "fuzz", *([host] if host else [])],  # as given, every parameter
        reproduce_options=_reproduce_options(classes, target_kind, allow_motion, server),
        command=shlex.join(["manip-conform", *sys.argv[1:]]),
        server={"server_faults": list(server_faults), "link": "chudp" if chudp else "stream", "wrist": wrist},
    )
    console.print(f"manip-conform fuzz: seed [bold]{seed}[/] (rerun with --seed {seed})")
    report = _campaign(config, server.fuzzed(seed), console, quiet, total=len(only) if only else inputs)
    report.unwritten.extend(write_reports(report, reports))
    _summary(console, report)
    for problem in report.unwritten:  # a report path that cannot be written is a usage error, found late
        click.echo(f"manip-conform: {problem}", err=True)
    sys.exit(int(report.exit_code))


def _reproduce_options(
    classes: tuple[str, ...], target_kind: str, allow_motion: bool, server: _Server
) -> list[str]:
    """The options of a violation's reproduce line: the classes, the target kind, the same server."""
    extra = [word for pattern in classes for word in ("--class", pattern)]
    if target_kind == "hardware":
        extra += ["--target", "hardware"] + (["--allow-motion"] if allow_motion else [])
    return extra + server.reproduce_options()


def _check_options(
    host: str | None,
    launch: str | None,
    server_log: Path | None,
    target_kind: str,
    allow_motion: bool,
    only: tuple[int, ...],
    server_faults: tuple[str, ...],
    classes: tuple[str, ...],
) -> None:
    """Usage errors of options that do not go together, or name what does not exist."""
    _check_server_choice(host)
    if launch is not None and (server_log is not None or given("restart_wait")):
        raise click.UsageError(
            "--launch reads the server's output and restarts it: not with --server-log or --restart-wait"
        )
    if allow_motion and target_kind != "hardware":
        raise click.UsageError("--allow-motion applies to --target hardware (a simulator gets every opcode)")
    if only and given("inputs"):
        raise click.UsageError("--only sends the inputs it names: not with --inputs")
    if server_faults:
        try:
            FaultSet.parse(server_faults)
        except ValueError as exc:
            raise click.UsageError(f"--server-fault: {exc}") from None
    for pattern in classes:
        if not any(match_id(pattern, c) for c in INPUT_CLASSES):
            raise click.UsageError(f"--class {pattern!r} matches no input class (--list-classes lists them)")


def _check_server_choice(host: str | None) -> None:
    """The options of the reference server the fuzzer starts go without HOST, those of HOST with it."""
    if host is not None:
        for name in ("server_faults", "link", "wrist"):
            if given(name):
                option = "--" + name.replace("_", "-").removesuffix("s")
                raise click.UsageError(
                    f"{option} applies to the reference server the fuzzer starts: omit HOST"
                )
        return
    for name in ("launch", "server_log", "restart_wait"):
        if given(name):
            raise click.UsageError(f"--{name.replace('_', '-')} applies to a HOST")


def _address(host: str | None) -> LinkAddress | None:
    """HOST's link address (None: the reference server the fuzzer starts); the fuzzer has no chaosd link."""
    if host is None:
        return None
    try:
        address = parse_address(host)
    except AddressError as exc:
        raise click.UsageError(str(exc)) from None
    if address.scheme == "chaosd":
        raise click.UsageError("the fuzzer speaks tcp://, unix:// and chudp:// links, not chaosd://")
    return address


@dataclass(frozen=True)
class _Server:
    """The server fuzzed, as the options name it: HOST (started by ``--launch``, or someone else's), or
    the reference server the fuzzer starts (its link, faults and wrist)."""

    address: LinkAddress | None
    link: str
    faults: tuple[str, ...]
    wrist: bool
    launch: str | None
    log: Path | None

    def fuzzed(self, seed: int) -> FuzzedServer:
        if self.address is None:
            argv = reference_server_argv(self.link, faults=self.faults, wrist=self.wrist, seed=seed)
            faults = f", faults: {', '.join(self.faults)}" if self.faults else ""
            wrist = ", simulated wrist" if self.wrist else ""
            return LaunchedServer(
                argv, label=f"the reference server (manip-server, {self.link}{wrist}{faults})"
            )
        if self.launch is not None:
            label = f"{self.address} (started with {self.launch})"
            return LaunchedServer(shlex.split(self.launch), self.address, label=label)
        return RemoteServer(self.address, self.log)

    def reproduce_options(self) -> list[str]:
        """The options of a reproduce line that start or find the same server."""
        extra: list[str] = []
        if self.address is None:
            extra += (["--link", self.link] if self.link != "tcp" else []) + (
                ["--wrist"] if self.wrist else []
            )
            for fault in self.faults:
                extra += ["--server-fault", fault]
        if self.launch is not None:
            extra += ["--launch", self.launch]
        if self.log is not None:
            extra += ["--server-log", str(self.log)]
        return extra


def _campaign(
    config: CampaignConfig, target: FuzzedServer, console: Console, quiet: bool, *, total: int
) -> RunReport:
    progress = progress_bar(console, quiet)
    task = progress.add_task("fuzz", total=total)

    started = time.monotonic()

    def batch_done(facts: CampaignFacts) -> None:
        rate = facts.rate(time.monotonic() - started)
        progress.update(task, completed=facts.inputs, description=f"fuzz {rate:.0f}/s")

    def found(violation: CampaignViolation) -> None:
        style = _STYLE.get(violation.kind, "bold red" if violation.counts else "yellow")
        progress.console.print(f"[{style}]{escape(violation.title())}[/]")

    def note(text: str) -> None:
        if not quiet:
            progress.console.print(f"[dim]{escape(text)}[/]")

    campaign = Campaign(config, target, CampaignEvents(batch_done, found, note))
    with progress:
        try:
            report = asyncio.run(campaign.run())
        except KeyboardInterrupt:
            report = campaign.finish()
            report.interrupted = True
        except Exception as exc:  # an internal error of the fuzzer: keep what was done
            report = campaign.finish()
            report.internal_error = traceback.format_exc()
            console.print(f"[bold magenta]internal error[/]: {type(exc).__name__}: {escape(str(exc))}")
    if not report.target:
        report.target = target.label
    return report


def _summary(console: Console, report: RunReport) -> None:
    facts = report.campaign
    assert isinstance(facts, CampaignFacts)
    for violation in facts.violations:
        console.print(violation_text(violation), markup=False, highlight=False)
    for problem in report.problems:
        console.print(f"[bold red]problem[/]: {escape(problem)}")
    if report.internal_error:
        console.print(report.internal_error, markup=False)
    style = "bold green" if report.exit_code == ExitCode.CONFORMANT else "bold red"
    console.print(f"target: {report.target}", markup=False)
    console.print(facts.summary_line(report.duration), markup=False)
    console.print(f"[{style}]{report.verdict}[/] (exit {int(report.exit_code)}); seed {report.seed}")
