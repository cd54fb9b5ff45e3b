"""``manip-server``: run the reference Puma server (a simulated arm) until interrupted.

Once every address is bound it prints one line per address on stdout, flushed, e.g.::

    manip-server: listening on tcp://127.0.0.1:42085 (contact PUMA)

so a script that asked for port 0 can read the real one.  SIGINT or SIGTERM stops it cleanly (exit 0);
a usage error (unknown fault, bad address) exits 2; a failure to bind, or to create the ``--record``
file, exits 1.

``--record FILE`` writes every packet of every connection, both ways, to an MCAP capture
(:mod:`manip.captures`; ``manip-capture info FILE`` lists it), with the seed and the command line in its
metadata.  The file is closed, complete, when the server stops (after the connections got their CLS),
also on SIGINT/SIGTERM; a server killed harder loses at most the last second (``manip-capture
recover``).
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
import signal
import sys
from collections.abc import Callable, Sequence
from contextlib import AbstractAsyncContextManager
from typing import TYPE_CHECKING, Any, Final

import click

from manip.arm.kinematics import PUMA600, ArmModel
from manip.cougar.link import parse_address as parse_drv11j_address
from manip.links import AddressError, ChaosError, NcpOptions, parse_address
from manip.links.address import DEFAULT_CONTACT, DEFAULT_TCP_PORT, Scheme
from manip.reference_server.cougar_wrist import make_cougar_wrist
from manip.reference_server.driver import DEFAULT_ADDRESS, ReferenceServer, serve
from manip.reference_server.faults import FAULTS, FaultSet
from manip.reference_server.session import ServerConfig

if TYPE_CHECKING:
    from manip.captures import Recorder
    from manip.links.api import LinkWrapper

__all__ = ["main"]

PROG: Final = "manip-server"

MODELS: Final[dict[str, ArmModel]] = {"puma600": PUMA600}
LOG_LEVELS: Final = ("DEBUG", "INFO", "WARNING", "ERROR")


def fault_listing() -> str:
    """Every fault switch: name, kind, what it does, the clauses involved and its argument."""
    lines = []
    for info in FAULTS.values():
        lines.append(f"{info.name}  [{info.kind}]")
        lines.append(f"    {info.description}")
        lines.append(f"    clauses: {', '.join(info.clauses)}")
        if info.argument is not None:
            lines.append(f"    argument: {info.name}={info.argument}")
    return "\n".join(lines)


def _faults(ctx: click.Context, param: click.Parameter, value: Sequence[str]) -> FaultSet:
    try:
        return FaultSet.parse(value)
    except ValueError as exc:
        raise click.BadParameter(str(exc), ctx=ctx, param=param) from None


def _address(url: str, param: str, scheme: Scheme) -> str:
    try:
        parsed = parse_address(url, default_scheme=scheme)
    except AddressError as exc:
        raise click.BadParameter(str(exc), param_hint=param) from None
    if param == "--chudp" and parsed.scheme != "chudp":
        raise click.BadParameter(f"{url!r} is not a chudp:// address", param_hint=param)
    return str(parsed)


class _Command(click.Command):
    """Keeps the arguments as given, for the command line a capture's metadata records."""

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        ctx.meta["manip.argv"] = list(args)
        return super().parse_args(ctx, args)


def command_line(ctx: click.Context) -> list[str]:
    """The program name and the arguments it was given (not ``sys.argv``: under a test runner or
    ``python -m`` that names something else)."""
    return [PROG, *ctx.meta.get("manip.argv", sys.argv[1:])]


@click.command(
    cls=_Command, context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100}
)
@click.option(
    "--listen",
    default=DEFAULT_ADDRESS,
    show_default=True,
    metavar="URL",
    help=f"Link address to listen on: tcp://HOST:PORT (manip's TCP link; {DEFAULT_TCP_PORT} is its "
    "port, 0 picks a free one), chudp://HOST:PORT?addr=OCTAL or chaosd:///PATH.",
)
@click.option(
    "--chudp",
    multiple=True,
    metavar="URL",
    help="Also listen on CHUDP (chudp://HOST:PORT?addr=OCTAL, the robot host's Chaos address); repeatable.",
)
@click.option("--contact", default=DEFAULT_CONTACT, show_default=True, help="Chaos contact name.")
@click.option(
    "--model", type=click.Choice(sorted(MODELS)), default="puma600", show_default=True, help="Arm model."
)
@click.option(
    "--time-scale",
    type=float,
    default=1.0,
    show_default=True,
    help="Simulated seconds per real second (e.g. 10: moves finish ten times sooner).",
)
@click.option("--seed", type=int, default=None, help="Seed of the server's random generator.")
@click.option(
    "--broken-after",
    type=click.FloatRange(min=0.1),
    default=None,
    metavar="SECONDS",
    help="Declare a connection broken when its client is silent this long (default 90, as the seed; "
    "shorter to check a client's or the suite's handling quickly).",
)
@click.option(
    "--fault",
    "faults",
    multiple=True,
    metavar="NAME[=ARG]",
    callback=_faults,
    help="Switch a fault on (see --list-faults); repeatable.",
)
@click.option("--list-faults", is_flag=True, help="List the fault switches and exit.")
@click.option("--powered", is_flag=True, help="Arm power on at connection (default: off, as on the Puma).")
@click.option(
    "--max-clients",
    type=click.IntRange(min=1),
    default=1,
    show_default=True,
    help="Connections open at once (one robot: 1; more is for benchmarks, each client then drives its "
    "own copy of the arm).",
)
@click.option(
    "--cougar",
    default=None,
    metavar="sim|URL",
    help="A Cougar wrist computer for the wrist opcodes: 'sim' (simulated in-process) or tcp://HOST:PORT "
    "(an external one over the emulated DRV-11J, e.g. manip-cougar). Default: none (wrist opcodes C UIM).",
)
@click.option(
    "--record",
    type=click.Path(dir_okay=False, writable=True),
    default=None,
    metavar="FILE",
    help="Record every connection's packets, both ways, to an MCAP capture FILE (see manip-capture).",
)
@click.option(
    "--log-level",
    type=click.Choice(LOG_LEVELS, case_sensitive=False),
    default="INFO",
    show_default=True,
    help="INFO logs one line per request.",
)
def main(
    listen: str,
    chudp: tuple[str, ...],
    contact: str,
    model: str,
    time_scale: float,
    seed: int | None,
    broken_after: float | None,
    faults: FaultSet,
    list_faults: bool,
    powered: bool,
    max_clients: int,
    cougar: str | None,
    record: str | None,
    log_level: str,
) -> None:
    """Run the manip reference Puma server: a simulated PUMA 600 speaking the Chaos manipulator protocol."""
    if list_faults:
        click.echo(fault_listing())
        return
    if not (time_scale > 0.0 and time_scale != float("inf")):
        raise click.BadParameter("must be a positive number", param_hint="--time-scale")
    address = _address(listen, "--listen", "tcp")
    if cougar is not None and cougar != "sim":
        try:
            parse_drv11j_address(cougar)
        except ValueError as exc:
            raise click.BadParameter(str(exc), param_hint="--cougar") from None
    extra = [_address(url, "--chudp", "chudp") for url in chudp]
    logging.basicConfig(
        level=log_level.upper(),
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    config = ServerConfig(model=MODELS[model], powered_at_open=powered, faults=faults)
    server = functools.partial(
        serve,
        address,
        config,
        contact=contact,
        time_scale=time_scale,
        seed=seed,
        max_clients=max_clients,
        extra_addresses=extra,
        wrist_factory=None if cougar is None else functools.partial(make_cougar_wrist, cougar, seed=seed),
        options=None if broken_after is None else NcpOptions.breaking_after(broken_after),
    )
    recording = None
    if record is not None:
        recording = functools.partial(
            _recording, record, seed=seed, command_line=command_line(click.get_current_context())
        )
    try:
        asyncio.run(_run(server, contact, recording))
    except (OSError, ChaosError) as exc:
        raise click.ClickException(f"cannot listen: {exc}") from exc


def _recording(path: str, *, seed: int | None, command_line: Sequence[str]) -> tuple[Recorder, LinkWrapper]:
    """A server capture at ``path`` and the link wrapper that records into it (call inside the running
    loop: the recorder's timer flushes it while the server is idle)."""
    # Imported here: the capture library (mcap, zstd: ~0.1 s) loads only when recording.
    from manip.captures import CaptureError, Recorder, RecorderTap  # noqa: PLC0415

    try:
        recorder = Recorder(path, how="server", seed=seed, command_line=command_line)
    except CaptureError as exc:
        raise click.ClickException(str(exc)) from exc
    return recorder, RecorderTap(recorder, "server").wrap


async def _run(
    server: Callable[..., AbstractAsyncContextManager[ReferenceServer]],
    contact: str,
    recording: Callable[[], tuple[Recorder, LinkWrapper]] | None = None,
) -> None:
    """Run ``server()`` until SIGINT or SIGTERM, recording it with what ``recording()`` makes."""
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError):  # no signal handlers on this platform
            loop.add_signal_handler(signum, stop.set)
    recorder: Recorder | None = None
    extra: dict[str, Any] = {}
    if recording is not None:
        recorder, extra["wrap_link"] = recording()
    try:
        async with server(**extra) as running:
            for bound in running.addresses:
                print(f"{PROG}: listening on {bound} (contact {contact})", flush=True)
            await stop.wait()
            _report(running)
    finally:
        # After the server's close, so the CLS each connection got is in the file.
        if recorder is not None:
            recorder.close()
            _report_recording(recorder)


def _report(server: ReferenceServer) -> None:
    stats = server.stats
    logging.getLogger("manip.reference_server").info(
        "stopping: %d connection(s), %d request(s), %d error(s) of which %d bad input(s), %d refused",
        stats.connections,
        stats.requests,
        stats.errors,
        stats.bad_inputs,
        stats.refused,
    )


def _report_recording(recorder: Recorder) -> None:
    logging.getLogger("manip.reference_server").info(
        "recorded %d message(s) to %s", sum(recorder.counts.values()), recorder.path
    )


if __name__ == "__main__":
    main()
