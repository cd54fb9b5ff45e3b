"""The ``replay`` and ``verify`` subcommands of ``manip-conform`` (registered by :mod:`.cli`), and the
capture that ``run --record`` writes.

Commands::

    manip-conform verify FILE [--session N]... [--strict] [--json F] [--junit F] [--html F] [--markdown F]
    manip-conform replay FILE [--against URL | --serve URL] [--session N]... [--ignore PATH]...
                              [--reply-timeout S] [--async-timeout S] [--settle S] [--seconds S]
                              [--server-fault NAME]... [--record OUT] [--strict] [--json F] [--junit F]
                              [--html F] [--markdown F]

``replay`` without ``--against`` or ``--serve`` replays against the embedded reference server, started
at the time scale and seed the capture's metadata name (the golden captures': 20 and 1985).
Exit codes are the suite's (erratum ``verify-exit-codes``): 0 conformant (and, for replay, every answer
as recorded), 1 not, 2 usage (a missing FILE, bad options), 3 the capture unreadable or holding no
session, or the target unreachable (``--serve``: no client came), 4 interrupted or internal error.
"""

from __future__ import annotations

import contextlib
import os
import shlex
import sys
import time
import traceback
from collections.abc import Awaitable, Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import click
from rich.console import Console
from rich.markup import escape

from manip.commandline import FiniteFloat, LinkAddressType
from manip.conformance.cli_options import check_output_paths, given, report_options, strict_option
from manip.conformance.output.console import make_console
from manip.conformance.output.documents import ReportPaths, write_reports
from manip.conformance.output.report import failure_text
from manip.conformance.output.run_console import OUTCOME_STYLE, print_by_clause, shown
from manip.conformance.suite.embedded import EmbeddedServer, simulated_server
from manip.conformance.suite.results import ExitCode, RunReport, completeness_text
from manip.exit_status import epilog

if TYPE_CHECKING:
    from manip.conformance.replay.verify import Judge
from manip.links import AddressError, parse_address, virtual_clock
from manip.links.api import LinkWrapper
from manip.reference_server import WRIST_OPERATIONS, FaultSet, ServerConfig
from manip.spec import SPEC
from manip.spec.constants import ServerOp

__all__ = [
    "EXIT_CODES_HELP",
    "check_output_paths",
    "given",
    "print_by_clause",
    "recording",
    "replay_command",
    "verify_command",
]

EXIT_CODES_HELP = epilog("manip-conform verify, replay")


@contextlib.contextmanager
def recording(
    path: str | os.PathLike[str] | None,
    *,
    how: str,
    side: str = "client",
    seed: int | None = None,
    virtual: bool = False,
) -> Iterator[LinkWrapper | None]:
    """A capture at ``path`` recording every link the yielded wrapper is given, as the ``side``
    (``client`` or ``server``) of the protocol; None (no wrapper) when ``path`` is None.  Enter it inside
    the running loop (the recorder's timer flushes it while the session is idle).  ``virtual``: the run
    is simulated; log times are its virtual clock (metadata ``time``: ``virtual``), so a replay can put
    every request at its recorded instant.  Its log times are still dates: the virtual clock anchored at
    the wall-clock start of the recording (metadata ``wall_origin_ns`` and ``virtual_origin_ns``, whose
    difference a replay takes off), so a viewer such as Foxglove shows when the run was made."""
    if path is None:
        yield None
        return
    # Imported here: the capture library (mcap, zstd) loads only when recording.
    from manip.captures import Recorder, RecorderTap  # noqa: PLC0415

    metadata = {"time": "virtual" if virtual else "real"}
    clock_ns: Callable[[], int] = time.time_ns
    if virtual:
        wall_origin, virtual_origin = time.time_ns(), virtual_clock.loop_clock_ns()
        metadata |= {"wall_origin_ns": str(wall_origin), "virtual_origin_ns": str(virtual_origin)}

        def clock_ns() -> int:
            return wall_origin + virtual_clock.loop_clock_ns() - virtual_origin

    with Recorder(
        path,
        how=how,
        seed=seed,
        command_line=["manip-conform", *sys.argv[1:]],
        metadata=metadata,
        clock_ns=clock_ns,
    ) as recorder:
        yield RecorderTap(recorder, "server" if side == "server" else "client").wrap


def _finish(
    report: RunReport,
    console: Console,
    quiet: bool,
    reports: ReportPaths,
) -> None:
    for result in report.results:
        if shown(result, quiet):
            style = OUTCOME_STYLE[result.outcome]
            console.print(f"[{style}]{result.outcome.upper():>10}[/] {result.id}")
            body = failure_text(result) if result.outcome != "error" else result.traceback.rstrip()
            if body:
                console.print(body, markup=False, highlight=False)
            for note in result.notes:
                console.print(f"           note: {note}", markup=False, highlight=False)
    report.unwritten.extend(write_reports(report, reports))
    print_by_clause(console, report)
    for problem in [*report.problems, *report.unwritten]:
        console.print(f"[bold red]problem[/]: {escape(problem)}")
    counts = ", ".join(f"{v} {k}" for k, v in report.counts().items() if v) or "no results"
    style = "bold green" if report.exit_code == ExitCode.CONFORMANT else "bold red"
    statuses = report.clause_statuses()
    console.print(
        f"[{style}]{report.verdict}[/] (exit {int(report.exit_code)}): {counts} in {report.duration:.1f} s"
        + (f"; {completeness_text(statuses)}" if statuses else "")
    )


def _run(
    job: Callable[[], Awaitable[RunReport]], console: Console, *, virtual: bool = False
) -> RunReport | int:
    try:
        return virtual_clock.run(job(), virtual=virtual)  # type: ignore[arg-type]
    except KeyboardInterrupt:
        console.print("[bold]interrupted[/]")
        return int(ExitCode.INTERNAL)
    except Exception as exc:
        console.print(f"[bold magenta]internal error[/]: {type(exc).__name__}: {escape(str(exc))}")
        console.print(traceback.format_exc(), markup=False, highlight=False)
        return int(ExitCode.INTERNAL)


# Shared with ``manip-conform run``.
_session_option = click.option(
    "--session",
    "sessions",
    multiple=True,
    type=click.IntRange(1),
    metavar="N",
    help="Only session N (1-based, in the order they started; repeatable).",
)
_file_argument = click.argument("file", type=click.Path(exists=True, dir_okay=False, path_type=Path))


# ----------------------------------------------------------------------------------------------- verify


@click.command("verify", epilog=EXIT_CODES_HELP)
@_file_argument
@_session_option
@strict_option
@click.option(
    "--judge",
    type=click.Choice(["server", "client", "both"]),
    default="server",
    show_default=True,
    help="Whose side of each session to judge: the server's answers, the client's requests, or both.",
)
@report_options
@click.option("-q", "--quiet", is_flag=True, help="Failures and the summary only.")
def verify_command(
    file: Path,
    sessions: tuple[int, ...],
    strict: bool,
    judge: Judge,
    reports: ReportPaths,
    quiet: bool,
) -> None:
    """Judge a recorded capture FILE offline with the suite's checks (request-number echo, reply
    shapes, error strings, asynchronous rules, describe-self...), citing clauses; with --judge client,
    the client's requests instead (opcodes, data layouts)."""
    from manip.conformance.replay.verify import verify_capture  # noqa: PLC0415

    check_output_paths(**reports.paths)
    console = make_console()
    command = shlex.join(["manip-conform", *sys.argv[1:]])
    try:
        report = verify_capture(file, strict=strict, sessions=sessions, command=command, judge=judge)
    except Exception as exc:
        console.print(f"[bold magenta]internal error[/]: {type(exc).__name__}: {escape(str(exc))}")
        console.print(traceback.format_exc(), markup=False, highlight=False)
        sys.exit(int(ExitCode.INTERNAL))
    _finish(report, console, quiet, reports)
    sys.exit(int(report.exit_code))


# ----------------------------------------------------------------------------------------------- replay


@dataclass(frozen=True)
class _Recorded:
    """How the server of a capture was set up, so the embedded server can be set up like it."""

    time_scale: float = 1.0
    seed: int | None = None
    wrist: bool = False
    """The recorded server had a wrist (it answered a wrist opcode normally)."""
    virtual: bool = False
    """A simulated run recorded it on its virtual clock: replay it in virtual time, each request at its
    recorded instant, and the embedded server goes through the same states."""
    clock_offset_ns: int = 0
    """Its log times less the virtual clock's (the wall-clock anchor of :func:`recording`)."""


def _capture_settings(file: Path) -> _Recorded:
    """What the capture's metadata and sessions say of its server (see :class:`_Recorded`)."""
    from manip.captures import CaptureError, read_capture  # noqa: PLC0415

    try:
        capture = read_capture(file)
    except CaptureError:
        return _Recorded()  # replay_capture reports the unreadable file
    meta = capture.metadata.get("manip.capture", {})
    try:
        scale = float(meta.get("time_scale", "") or 1.0)
    except ValueError:
        scale = 1.0
    seed_text = meta.get("seed", "")
    wrist_ops = {SPEC.request(name).opcode for name in WRIST_OPERATIONS}
    wrist = any(
        pair.request.packet is not None
        and pair.request.packet.opcode in wrist_ops
        and any(r.packet is not None and r.packet.opcode == ServerOp.RESPONSE for r in pair.replies)
        for session in capture.sessions
        for pair in session.pairs.values()
    )
    seed = int(seed_text) if seed_text.isdigit() else None
    virtual = meta.get("time") == "virtual" and seed is not None
    origins = meta.get("wall_origin_ns", ""), meta.get("virtual_origin_ns", "")
    offset = int(origins[0]) - int(origins[1]) if all(o.isdigit() for o in origins) else 0  # older: none
    return _Recorded(scale, seed, wrist, virtual, offset)


@click.command("replay", epilog=EXIT_CODES_HELP)
@_file_argument
@click.option(
    "--against",
    "against",
    metavar="URL",
    type=LinkAddressType(parse_address),
    help="Replay the client side to the server at URL.",
)
@click.option(
    "--serve",
    "serve",
    metavar="URL",
    type=LinkAddressType(parse_address),
    help="Play the server side to clients at URL (port 0: a free one).",
)
@_session_option
@click.option(
    "--ignore",
    "ignore",
    multiple=True,
    metavar="PATH",
    help="Leave out mismatches whose field path matches PATH (glob: error.message, describe.*).",
)
@click.option("--reply-timeout", type=FiniteFloat(0.01), default=2.0, show_default=True,
              help="Seconds to wait for each live answer.")  # fmt: skip
@click.option("--async-timeout", type=FiniteFloat(0.01), default=10.0, show_default=True,
              help="Seconds to wait for each recorded asynchronous packet's counterpart.")  # fmt: skip
@click.option("--settle", type=FiniteFloat(0.0), default=0.2, show_default=True,
              help="Seconds of quiet listened for after each session (extra packets).")  # fmt: skip
@click.option("--seconds", type=FiniteFloat(0.01), default=None,
              help="--serve: stop after this many seconds even if sessions are left.")  # fmt: skip
@click.option(
    "--server-fault",
    "server_faults",
    multiple=True,
    metavar="NAME[=ARG]",
    help="Embedded server only: switch on a fault of the reference server.",
)
@click.option(
    "--record",
    "record",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Record the live side to an MCAP capture (then: manip-conform verify OUT).",
)
@click.option("--strict", is_flag=True, help="SHOULD failures of the live checks count.")
@report_options
@click.option("-q", "--quiet", is_flag=True, help="Failures and the summary only.")
def replay_command(
    file: Path,
    against: str | None,
    serve: str | None,
    sessions: tuple[int, ...],
    ignore: tuple[str, ...],
    reply_timeout: float,
    async_timeout: float,
    settle: float,
    seconds: float | None,
    server_faults: tuple[str, ...],
    record: Path | None,
    strict: bool,
    reports: ReportPaths,
    quiet: bool,
) -> None:
    """Replay a recorded capture FILE: its client side to a live server (--against URL; without it the
    embedded reference server), comparing every answer with the recording (masks: erratum
    replay-masking), or its server side to a client under test (--serve URL)."""
    from manip.conformance.replay.against import ReplayOptions, replay_capture  # noqa: PLC0415
    from manip.conformance.replay.serve import ServeOptions, serve_capture  # noqa: PLC0415

    console = make_console()
    if against and serve:
        raise click.UsageError("give --against URL or --serve URL, not both")
    try:
        for url in (against, serve):
            if url:
                parse_address(url)
    except AddressError as exc:
        raise click.UsageError(str(exc)) from None
    if server_faults and (against or serve):
        raise click.UsageError("--server-fault applies to the embedded server only (omit --against/--serve)")
    if seconds is not None and not serve:
        raise click.UsageError("--seconds applies to --serve")
    if serve:
        for name in ("reply_timeout", "async_timeout", "settle"):
            if given(name):
                option = "--" + name.replace("_", "-")
                raise click.UsageError(f"{option} applies to a replay against a server, not to --serve")
    try:
        faults = FaultSet.parse(server_faults) if server_faults else None
    except ValueError as exc:
        raise click.UsageError(f"--server-fault: {exc}") from None
    check_output_paths(record=record, **reports.paths)
    command = shlex.join(["manip-conform", *sys.argv[1:]])

    if serve:

        def listening(address: str) -> None:
            console.print(
                f"manip-conform: serving the recorded sessions of {file} at {address}", markup=False
            )
            sys.stdout.flush()

        async def serve_job() -> RunReport:
            with recording(record, how="manip-conform replay --serve", side="server") as wrap:
                options = ServeOptions(
                    seconds=seconds,
                    ignore=ignore,
                    strict=strict,
                    sessions=sessions,
                    wrap_link=wrap,
                    on_listening=listening,
                )
                return await serve_capture(file, serve, options, command=command)

        outcome = _run(serve_job, console)
    else:
        recorded = _Recorded() if against else _capture_settings(file)
        virtual = recorded.virtual

        async def replay_job() -> RunReport:
            with recording(record, how="manip-conform replay", virtual=virtual) as wrap:
                options = ReplayOptions(
                    reply_timeout=reply_timeout,
                    async_timeout=async_timeout,
                    settle=settle,
                    ignore=ignore,
                    strict=strict,
                    sessions=sessions,
                    wrap_link=wrap,
                    paced=virtual,
                    clock_offset_ns=recorded.clock_offset_ns,
                )
                if against:
                    return await replay_capture(file, against, options, command=command)
                config = ServerConfig() if faults is None else ServerConfig(faults=faults)
                reproduce = ["manip-conform", "replay", str(file)]
                for fault in server_faults:
                    reproduce += ["--server-fault", fault]
                if virtual:
                    assert recorded.seed is not None
                    async with simulated_server(config, seed=recorded.seed, wrist=recorded.wrist) as address:
                        console.print(
                            f"embedded reference server in virtual time (seed {recorded.seed}, as recorded)",
                            markup=False,
                        )
                        return await replay_capture(
                            file, address, options, embedded=True, command=command, reproduce=reproduce
                        )
                scale = recorded.time_scale
                with EmbeddedServer(
                    config, time_scale=scale, seed=recorded.seed, wrist=recorded.wrist
                ) as address:
                    console.print(
                        f"embedded reference server at {address} (time scale {scale:g})", markup=False
                    )
                    return await replay_capture(
                        file, address, options, embedded=True, command=command, reproduce=reproduce
                    )

        outcome = _run(replay_job, console, virtual=virtual)
    if isinstance(outcome, int):
        sys.exit(outcome)
    _finish(outcome, console, quiet, reports)
    sys.exit(int(outcome.exit_code))
