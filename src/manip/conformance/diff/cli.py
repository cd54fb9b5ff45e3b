"""``manip-conform diff A B``: two servers, the same request streams, every difference classified.

A and B are each a link address (``tcp://HOST:PORT``, ``unix:///PATH``) or ``embedded``: the reference
server in virtual time, shaped by ``--server-fault-a/-b``, ``--server-profile-a/-b`` and
``--error-args-a/-b``, and reached over ``--link`` (a Unix socket, CHUDP, or chaosd).  See
:mod:`manip.conformance.diff.driver` for what is sent and :mod:`manip.conformance.diff.classify` for the
classes.
"""

from __future__ import annotations

import os
import shlex
import sys
import time
import traceback
from dataclasses import replace
from typing import Any

import click
from rich.markup import escape

from manip.arm.units import LENGTH_UNITS, LengthUnit
from manip.commandline import FiniteFloat, broken_after_option
from manip.conformance.cli_options import check_output_paths, format_options
from manip.conformance.diff.driver import DiffConfig, StreamResult, run_diff
from manip.conformance.diff.report import DIFF_FORMATS, DiffReport, finding_lines
from manip.conformance.diff.scenarios import SCENARIOS, scenario, scenarios
from manip.conformance.diff.sides import Side, input_link, reachable
from manip.conformance.diff.streams import Stream, make_stream, make_streams, stream_of
from manip.conformance.fuzz.generators import GenOptions
from manip.conformance.fuzz.session import Allowance
from manip.conformance.output.console import make_console
from manip.conformance.output.documents import write_formats
from manip.conformance.suite.context import DEFAULT_CONNECT_TIMEOUT, DEFAULT_REPLY_TIMEOUT
from manip.exit_status import epilog
from manip.links import AddressError, parse_address
from manip.reference_server import FaultSet
from manip.reference_server.session import PROFILES, server_config

__all__ = ["diff_command"]

EMBEDDED = "embedded"


def _side_options(letter: str) -> list[Any]:
    lower = letter.lower()
    return [
        click.option(
            f"--server-fault-{lower}",
            f"faults_{lower}",
            multiple=True,
            metavar="NAME[=ARG]",
            help=f"Side {letter} embedded: switch a fault of the reference server on (repeatable; "
            "manip-server --list-faults).",
        ),
        click.option(
            f"--server-profile-{lower}",
            f"profile_{lower}",
            type=click.Choice(PROFILES),
            default="manip",
            show_default=True,
            help=f"Side {letter} embedded: the reference server's profile (guide: as written from the "
            "1985 guide alone).",
        ),
        click.option(
            f"--error-args-{lower}",
            f"error_args_{lower}",
            type=click.Choice(["aligned", "packed"]),
            default=None,
            help=f"Side {letter} embedded: the layout of an error string's numbers "
            "(erratum error-arg-layout).",
        ),
        click.option(
            f"--length-unit-{lower}",
            f"unit_{lower}",
            type=click.Choice(LENGTH_UNITS),
            default=None,
            help=f"Side {letter}'s unit of lengths (erratum units): an embedded server's (default: its "
            "profile's); the unit an addressed side uses (default mm), as manip-conform run "
            "--length-unit names a target's.",
        ),
        click.option(
            f"--world-{lower}",
            f"world_{lower}",
            metavar="tcp://HOST:PORT|COMMAND",
            default=None,
            help=f"Side {letter} addressed: its world (contract 2, docs/world-harness.md), which arranges "
            "the conditions the world's scenarios need; without it they are not sent to that side.",
        ),
    ]


def _with_sides(f: Any) -> Any:
    for option in [*_side_options("B"), *_side_options("A")]:
        f = option(f)
    return f


def _numbers(ctx: click.Context, param: click.Parameter, value: str | None) -> tuple[int, ...] | None:
    if value is None:
        return None
    try:
        numbers = tuple(int(x) for x in value.replace(" ", "").split(",") if x)
    except ValueError:
        raise click.BadParameter(f"{value!r} is not a list of input numbers (e.g. 12,40)") from None
    if any(n < 0 for n in numbers):
        raise click.BadParameter("give input numbers 0 and up, comma separated")
    return numbers


@click.command("diff", epilog=epilog("manip-conform diff"))
@click.argument("a")
@click.argument("b")
@_with_sides
@click.option(
    "--seed", type=click.IntRange(0, 2**31 - 1), default=None, help="Seed of the streams (default: random)."
)
@click.option(
    "--streams",
    "count",
    type=click.IntRange(1, 100_000),
    default=20,
    show_default=True,
    help="Streams to send.",
)
@click.option(
    "--length", type=click.IntRange(1, 200), default=8, show_default=True, help="Fuzz inputs per stream."
)
@click.option(
    "--link",
    type=click.Choice(["unix", "chudp", "chaosd"]),
    default="unix",
    show_default=True,
    help="How the embedded sides are reached: a Unix socket with manip's TCP link framing, CHUDP on a "
    "loopback UDP port (its framing judged too; the streams then draw the datagram link's inputs), or "
    "usim's chaosd framing through a routing chaosd stand-in in the process (its framing judged too).  "
    "Both sides embedded.",
)
@click.option("--stream", "only_stream", type=click.IntRange(0), default=None, help="Send only stream N.")
@click.option(
    "--scenario",
    "only_scenario",
    type=click.Choice(list(SCENARIOS)),
    default=None,
    help="Send only this scenario (a directed case's request sequence).",
)
@click.option(
    "--scenarios/--no-scenarios",
    "with_scenarios",
    default=True,
    show_default=True,
    help="Send the scenarios (the directed cases' request sequences, each with its judge) before the "
    "generated streams.",
)
@click.option(
    "--inputs",
    "only_inputs",
    callback=_numbers,
    default=None,
    help="Send one stream of exactly these inputs (a shrunk one).",
)
@click.option(
    "--class",
    "classes",
    multiple=True,
    metavar="PATTERN",
    help="Draw the streams' inputs only from these fuzz input classes (glob, repeatable; "
    "manip-conform fuzz --list-classes).",
)
@click.option("--no-shrink", is_flag=True, help="Do not shrink the streams of unexplained differences.")
@click.option(
    "--allow-unexplained",
    is_flag=True,
    help="Unexplained differences (gaps in the spec) warn and do not fail.",
)
@click.option(
    "--reply-timeout",
    type=FiniteFloat(min=0.01),
    default=DEFAULT_REPLY_TIMEOUT,
    show_default=True,
    help="Seconds an answer may take.",
)
@click.option(
    "--connect-timeout",
    type=FiniteFloat(min=0.01),
    default=DEFAULT_CONNECT_TIMEOUT,
    show_default=True,
    help="Seconds a connection may take to open.",
)
@broken_after_option(
    "Both sides' broken-connection timer (90 s on manip's NCP, the ITS Chaos NCP's: the 1985 guide "
    "gives none; erratum ncp-timers), as manip-conform run --broken-after: an embedded side's server is "
    "given it, an addressed side is declared to use it.  With it the silent-peer scenario is sent: its "
    "connection falls silent that long and a margin, and must then be found given up (ncp.broken); "
    "without it that scenario is not sent."
)
@format_options(DIFF_FORMATS)
@click.option("-q", "--quiet", is_flag=True, help="No line per stream; the findings and the summary only.")
def diff_command(**options: Any) -> None:
    """Send the same request streams (the fuzzer's inputs, from one seed) to servers A and B, each stream
    from the same start, pair their answers request by request, and classify every difference: (a) a
    violation (one side breaks a clause, named; the other's answer conforms), (b) both allowed (an
    erratum or a clause's declared freedom says so, named), (c) unexplained (a candidate gap in the spec,
    shrunk, with the nearest section of the 1985 guide).  A and B: a link address, or "embedded" (the
    reference server in virtual time, shaped by the -a/-b options)."""
    sides = (_side("A", options), _side("B", options))
    check_output_paths(**options["reports"].paths)
    chosen = [options[k] is not None for k in ("only_stream", "only_inputs", "only_scenario")]
    if sum(chosen) > 1:
        raise click.UsageError("--stream, --inputs and --scenario each choose what is sent: give one")
    seed = options["seed"] if options["seed"] is not None else int.from_bytes(os.urandom(4), "big") >> 1
    link = options["link"]
    if link != "unix" and not all(side.embedded for side in sides):
        raise click.UsageError(f"--link {link} reaches embedded sides: give both as {EMBEDDED}")
    timer = options["broken_after"]
    sides = (
        replace(sides[0], link=link, broken_after=timer),
        replace(sides[1], link=link, broken_after=timer),
    )
    gen = GenOptions(link=input_link(link), select=options["classes"])
    if not gen.classes():
        raise click.UsageError("--class matches no input class (manip-conform fuzz --list-classes)")
    length = options["length"]
    streams = _streams(seed, options, gen)
    allowance = Allowance(options["reply_timeout"], options["connect_timeout"])
    config = DiffConfig(seed, allowance, shrink=not options["no_shrink"])
    report = DiffReport(
        sides[0].label,
        sides[1].label,
        seed,
        length,
        shlex.join(["manip-conform", *sys.argv[1:]]),
        (
            "manip-conform",
            "diff",
            *sides[0].words,
            *sides[1].words,
            *(("--link", link) if link != "unix" else ()),
            *(("--broken-after", f"{timer:g}") if timer is not None else ()),
            *[w for c in options["classes"] for w in ("--class", c)],
        ),
        allow_unexplained=options["allow_unexplained"],
    )
    console = make_console()
    console.print(f"manip-conform diff: seed [bold]{seed}[/] (rerun with --seed {seed})")
    _run(report, sides, streams, config, console, quiet=options["quiet"])
    _write(report, options)
    _summary(report, console)
    sys.exit(report.exit_code)


def _streams(seed: int, options: dict[str, Any], gen: GenOptions) -> list[Stream]:
    if options["only_scenario"] is not None:
        return [scenario(options["only_scenario"])]
    if options["only_inputs"] is not None:
        return [stream_of(seed, options["only_inputs"], gen)]
    if options["only_stream"] is not None:
        return [make_stream(seed, options["only_stream"], options["length"], gen)]
    made = make_streams(seed, options["count"], options["length"], gen)
    return [*scenarios(), *made] if options["with_scenarios"] else made


def _side(letter: str, options: dict[str, Any]) -> Side:
    """Side ``letter`` as the command line names it; a usage error for options that do not apply."""
    lower = letter.lower()
    target = options[lower]
    faults, profile, error_args, unit, world = (
        options[f"faults_{lower}"],
        options[f"profile_{lower}"],
        options[f"error_args_{lower}"],
        options[f"unit_{lower}"],
        options[f"world_{lower}"],
    )
    if target == EMBEDDED and world is not None:
        raise click.UsageError(
            f"--world-{lower} is an addressed side's world: the embedded server has its own, in-process"
        )
    if target != EMBEDDED:
        if faults or profile != "manip" or error_args is not None:
            raise click.UsageError(
                f"the --...-{lower} server options apply to an embedded side {letter} only"
            )
        return _addressed(letter, target, unit, world)
    try:
        fault_set = FaultSet.parse(faults)
    except ValueError as exc:
        raise click.UsageError(f"--server-fault-{lower}: {exc}") from None
    changes: dict[str, Any] = {"faults": fault_set}
    words = [EMBEDDED, *[w for f in faults for w in (f"--server-fault-{lower}", f)]]
    if error_args is not None:
        changes["error_args"] = error_args
        words += [f"--error-args-{lower}", error_args]
    if unit is not None:
        changes["length_unit"] = unit
        words += [f"--length-unit-{lower}", unit]
    if profile != "manip":
        words += [f"--server-profile-{lower}", profile]
    config = server_config(profile, **changes)
    label = " ".join(["the reference server", f"(profile {profile}", *(f"fault {f}" for f in faults)]) + (
        f", error args {error_args}" if error_args else ""
    )
    label += f", lengths in {unit})" if unit else ")"
    return Side(letter, label, config=config, words=tuple(words))


def _addressed(letter: str, target: str, unit: LengthUnit | None, world: str | None) -> Side:
    """Side ``letter`` at the address ``target``, its declared length unit, its world."""
    lower = letter.lower()
    try:
        address = parse_address(target)
    except AddressError as exc:
        raise click.UsageError(f"{letter}: {exc}") from None
    if address.scheme not in ("tcp", "unix"):
        raise click.UsageError(f"{letter}: diff speaks tcp:// and unix:// links, not {address.scheme}://")
    words = [target]
    if unit is not None:
        words += [f"--length-unit-{lower}", unit]
    if world is not None:
        words += [f"--world-{lower}", world]
    return Side(letter, str(address), address=address, words=tuple(words), world=world, unit=unit or "mm")


def _run(
    report: DiffReport,
    sides: tuple[Side, Side],
    streams: list[Stream],
    config: DiffConfig,
    console: Any,
    *,
    quiet: bool,
) -> None:
    started = time.monotonic()
    for side in sides:
        why = reachable(side, config.allowance, config.seed)
        if why is not None:
            report.unreachable = True
            report.problems.append(f"side {side.name} ({side.label}) is unreachable: {why}")
            return

    def done(result: StreamResult) -> None:
        report.results.append(result)
        if not quiet:
            state = (
                f"not compared: {result.unarranged}"
                if result.unarranged
                else "unstable"
                if result.unstable
                else f"{len(result.findings)} difference(s)"
            )
            console.print(f"[dim]{escape(result.stream.label)}: {state} ({result.seconds:.2f} s)[/]")

    try:
        run_diff(sides[0], sides[1], streams, config, done)
    except KeyboardInterrupt:
        report.interrupted = True
        report.problems.append("the diff was interrupted; this report is partial")
    except Exception as exc:  # an internal error of the diff: keep what was done
        report.internal_error = traceback.format_exc()
        console.print(f"[bold magenta]internal error[/]: {type(exc).__name__}: {escape(str(exc))}")
    report.seconds = time.monotonic() - started


def _write(report: DiffReport, options: dict[str, Any]) -> None:
    problems = write_formats(report, options["reports"], DIFF_FORMATS)
    for problem in problems:
        click.echo(f"manip-conform: {problem}", err=True)
    if problems:
        sys.exit(2)


def _stream_notes(report: DiffReport) -> list[str]:
    """What the streams did that is no finding: runaways, scenarios not compared, checks not judged."""
    out = [f"runaway: {r.stream.label}: side {d}" for r in report.results for d in r.runaway]
    out += [f"not compared: {r.stream.label}: {r.unarranged}" for r in report.results if r.unarranged]
    return out + [f"not judged: {r.stream.label}: {d}" for r in report.results for d in r.unjudged]


def _summary(report: DiffReport, console: Any) -> None:
    allowed: dict[tuple[tuple[str, ...], tuple[str, ...]], list[str]] = {}
    for result in report.results:
        for finding in result.findings:
            if finding.cls == "allowed":  # grouped: the same freedom shows again and again
                where = f"{finding.stream} input {finding.difference.number}"
                allowed.setdefault((finding.freedoms, finding.names), []).append(where)
                continue
            console.print("\n".join(finding_lines(report, finding, result)), markup=False, highlight=False)
    for (parts, names), wheres in allowed.items():
        console.print(
            f"(b) both allowed: {', '.join(parts)} [{', '.join(names)}]: {len(wheres)} time(s), first in "
            f"{wheres[0]} (every one in the JSON and Markdown reports)",
            markup=False,
            highlight=False,
        )
    for line in _stream_notes(report):
        console.print(line, markup=False)
    for result in report.unstable:
        console.print(f"unstable (no finding): {result.stream.label}: {result.unstable_detail}", markup=False)
    for problem in report.problems:
        console.print(f"[bold red]problem[/]: {escape(problem)}")
    if report.internal_error:
        console.print(report.internal_error, markup=False)
    console.print(f"A: {report.a}\nB: {report.b}", markup=False)
    console.print(report.summary_line(), markup=False)
    style = "bold green" if report.exit_code == 0 else "bold red"
    console.print(f"[{style}]{report.verdict}[/] (exit {report.exit_code}); seed {report.seed}")
