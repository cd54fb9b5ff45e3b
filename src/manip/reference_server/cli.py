"""``manip-server``: run the reference Puma server (a simulated arm) until interrupted.

Once every address is bound it prints one line per address on stdout, flushed, e.g.::

    manip-server: listening on tcp://127.0.0.1:42085 (contact PUMA)

so a script that asked for port 0 can read the real one; with ``--world`` the next line says where the
robot's world listens (``manip-server: world on tcp://127.0.0.1:PORT``,
:mod:`manip.reference_server.world`).  SIGINT or SIGTERM stops it cleanly (exit 0);
a usage error (unknown fault, bad address) exits 2; a failure to bind, or to create the ``--record``
file, exits 1.

Links are bounded and access is ruled (:mod:`manip.links.guard`): ``--frame-timeout``,
``--link-idle-timeout`` and ``--max-links`` bound what a peer can hold; ``--allow`` (repeatable) names
who may connect, by IP address or network and by Chaos address.  Listening on anything but loopback
without an IP ``--allow`` prints a warning: the 1985 protocol has no authentication, so anyone who can
reach the port can move the arm.  ``--stats`` prints one line of link counters at exit; SIGUSR1 prints
it at any time.

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
import ipaddress
import logging
import signal
import sys
from collections import Counter
from collections.abc import AsyncIterator, Callable, Sequence
from contextlib import AbstractAsyncContextManager
from typing import TYPE_CHECKING, Any, Final

import click

from manip.arm.kinematics import PUMA600, ArmModel
from manip.arm.units import LENGTH_UNITS, LengthUnit
from manip.codecs.messages import AsyncLayout
from manip.commandline import (
    FINITE,
    FiniteFloat,
    LinkAddressType,
    broken_after_option,
    check_host,
    configure_logging,
    version_option,
)
from manip.cougar.link import parse_drv11j_address
from manip.exit_status import epilog
from manip.links import (
    AccessError,
    AccessList,
    AddressError,
    ChaosError,
    LinkAddress,
    LinkLimits,
    NcpConfig,
    parse_address,
)
from manip.links.address import DEFAULT_CONTACT, DEFAULT_TCP_PORT, Scheme
from manip.links.guard import DEFAULT_FRAME_TIMEOUT, DEFAULT_IDLE_TIMEOUT, DEFAULT_MAX_LINKS
from manip.reference_server.conditions import WorldCondition
from manip.reference_server.cougar_wrist import make_cougar_wrist
from manip.reference_server.driver import DEFAULT_ADDRESS, ReferenceServer, serve
from manip.reference_server.faults import Fault, FaultSet
from manip.reference_server.session import (
    PROFILES,
    ConfigurationBits,
    ErrorArgs,
    server_config,
)
from manip.reference_server.world import ReferenceWorld, serve_world

if TYPE_CHECKING:
    from manip.captures import Recorder
    from manip.links.api import LinkWrapper

__all__ = ["main"]

PROG: Final = "manip-server"

MODELS: Final[dict[str, ArmModel]] = {"puma600": PUMA600}
LOG_LEVELS: Final = ("DEBUG", "INFO", "WARNING", "ERROR")


def fault_listing() -> str:
    """Every name ``--fault`` takes: the world's conditions (``environment``), then the fault switches
    (``protocol``), each with what it does, the clauses involved and its argument."""
    lines = []
    conditions = [(c, "environment", c.description) for c in WorldCondition]
    switches = conditions + [(f, f.kind, f.breaks) for f in Fault]
    for switch, kind, what in switches:
        lines.append(f"{switch.value}  [{kind}]")
        lines.append(f"    {what}")
        lines.append(f"    clauses: {', '.join(switch.clauses)}")
        if switch.argument is not None:
            lines.append(f"    argument: {switch.value}={switch.argument}")
    return "\n".join(lines)


def _faults(ctx: click.Context, param: click.Parameter, value: Sequence[str]) -> FaultSet:
    try:
        return FaultSet.parse(value)
    except ValueError as exc:
        raise click.BadParameter(str(exc), ctx=ctx, param=param) from None


def _allow(ctx: click.Context, param: click.Parameter, value: Sequence[str]) -> AccessList:
    try:
        return AccessList.parse(value)
    except AccessError as exc:
        raise click.BadParameter(str(exc), ctx=ctx, param=param) from None


def _off_if_zero(value: float) -> float | None:
    return None if value == 0 else value


def exposure_warning(address: LinkAddress, access: AccessList) -> str | None:
    """The warning for listening on ``address`` with ``access``: None on loopback (or a chaosd
    socket, reached only from this machine) or when IP rules say who may connect."""
    if address.scheme == "chaosd" or access.restricts_ip:
        return None
    try:
        if ipaddress.ip_address(address.host).is_loopback:
            return None
    except ValueError:
        if address.host == "localhost":
            return None
    where = f"{address.scheme}://{address.host}:{address.port}"
    line = (
        f"{PROG}: warning: {where} is not loopback and no --allow names who may connect: anyone who "
        "can reach this port can move the arm (the 1985 protocol has no authentication)."
    )
    if access.restricts_chaos:
        line += " Chaos address rules alone do not stop them: a peer writes its own Chaos address."
    return line + " Give --allow ADDRESS or NETWORK, or listen on 127.0.0.1."


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
    cls=_Command,
    context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100},
    epilog=epilog("manip-server"),
)
@click.option(
    "--listen",
    default=DEFAULT_ADDRESS,
    show_default=True,
    metavar="URL",
    type=LinkAddressType(parse_address),
    help=f"Link address to listen on: tcp://HOST:PORT (manip's TCP link; {DEFAULT_TCP_PORT} is its "
    "port, 0 picks a free one), chudp://HOST:PORT?addr=OCTAL or chaosd:///PATH.",
)
@click.option(
    "--chudp",
    multiple=True,
    metavar="URL",
    type=LinkAddressType(parse_address, "chudp", ("chudp",)),
    help="Also listen on CHUDP (chudp://HOST:PORT?addr=OCTAL, the robot host's Chaos address); repeatable.",
)
@click.option("--contact", default=DEFAULT_CONTACT, show_default=True, help="Chaos contact name.")
@click.option(
    "--model", type=click.Choice(sorted(MODELS)), default="puma600", show_default=True, help="Arm model."
)
@click.option(
    "--time-scale",
    type=FINITE,
    default=1.0,
    show_default=True,
    help="Simulated seconds per real second (e.g. 10: moves finish ten times sooner).",
)
@click.option("--seed", type=int, default=None, help="Seed of the server's random generator.")
@broken_after_option(
    "Declare a connection broken when its client is silent this long (default 90, the ITS Chaos "
    "NCP's interval: the 1985 guide gives none; erratum ncp-timers; shorter to check a client's or the "
    "suite's handling quickly)."
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
@click.option(
    "--profile",
    type=click.Choice(PROFILES),
    default="manip",
    show_default=True,
    help="manip: the reference server as manip documents it. guide: as a server written from the 1985 "
    "guide alone would be (no extension opcodes, lengths in inches, asynchronous responses in the "
    "guide's 6-byte layout, configuration bits besides bit 0 answered with done); the options below "
    "change single choices of either.",
)
@click.option(
    "--error-args",
    type=click.Choice(["aligned", "packed"]),
    default=None,
    help="Layout of the numbers after an error string's NUL, both conformant (erratum error-arg-layout): "
    "aligned to an even offset by a zero pad byte (the default), or packed straight after the NUL as in "
    "the 1985 guide's NZI example.",
)
@click.option(
    "--async-layout",
    type=click.Choice(["numbered", "guide"]),
    default=None,
    help="Layout of an asynchronous response (0203), both conformant (erratum async-request-number): "
    "numbered, the last request's number first (8 bytes, profile manip), or the 1985 guide's condition "
    "code and two words (6 bytes, profile guide).",
)
@click.option(
    "--length-unit",
    type=click.Choice(LENGTH_UNITS),
    default=None,
    help="Unit of lengths on the wire (erratum units): transforms' positions and incremental moves' dX "
    "dY dZ (mm for profile manip, inch for profile guide); the arm model stays in millimetres.",
)
@click.option(
    "--configuration-bits",
    type=click.Choice(["refuse", "done"]),
    default=None,
    help="Set configuration with bits besides bit 0 (erratum set-configuration): refuse with C BVA "
    "(profile manip) or answer done and use bit 0 (profile guide), both conformant.",
)
@click.option("--powered", is_flag=True, help="Arm power on at connection (default: off, as on the Puma).")
@click.option(
    "--no-extensions",
    is_flag=True,
    help="Behave as a server written from the 1985 guide alone: refuse manip's Puma extension opcodes "
    "(0240 and up: the wrist, request notifications, reset abort) as unknown (C UOP) and leave them out "
    "of describe self.",
)
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
    "--allow",
    multiple=True,
    callback=_allow,
    metavar="RULE",
    help="Who may connect; repeatable; everyone else is refused. An IP address or network for TCP and "
    "CHUDP peers (127.0.0.1, 10.0.0.0/8, ::1) or a Chaos address or range for RFCs (chaos:0401, "
    "chaos:0400-0477, octal). A kind not given restricts nothing. Default: everyone (with a warning "
    "unless on loopback).",
)
@click.option(
    "--frame-timeout",
    type=FiniteFloat(min=0.0),
    default=DEFAULT_FRAME_TIMEOUT,
    show_default=True,
    metavar="SECONDS",
    help="Close a TCP link whose first frame, or any frame once begun, is not complete within SECONDS "
    "(0: never).",
)
@click.option(
    "--link-idle-timeout",
    type=FiniteFloat(min=0.0),
    default=DEFAULT_IDLE_TIMEOUT,
    show_default=True,
    metavar="SECONDS",
    help="Close a TCP link that carries no Chaos connection for SECONDS, from its opening or its last "
    "connection's end (0: never).",
)
@click.option(
    "--max-links",
    type=click.IntRange(min=0),
    default=DEFAULT_MAX_LINKS,
    show_default=True,
    metavar="N",
    help="TCP links open at once (0: no limit). A new one beyond it displaces the oldest link without a "
    "Chaos connection, or is closed at once if every link has one.",
)
@click.option(
    "--accept-backoff",
    type=FiniteFloat(min=0.001),
    default=1.0,
    show_default=True,
    metavar="SECONDS",
    help="Pause accepting TCP connections this long when out of file descriptors (then logged at most "
    "once per 10 s, with a count).",
)
@click.option(
    "--stats",
    "show_stats",
    is_flag=True,
    help="Print one line of link counters at exit: accepted, refused by reason, idle-closed, over-limit, "
    "accept errors, bad frames (SIGUSR1 prints it at any time).",
)
@click.option(
    "--log-level",
    type=click.Choice(LOG_LEVELS, case_sensitive=False),
    default="INFO",
    show_default=True,
    help="INFO logs one line per request.",
)
@click.option(
    "--world",
    "world",
    default=None,
    metavar="tcp://HOST:PORT",
    help="Also serve the robot's world (contract 2, docs/world-harness.md) on this address, so that "
    "manip-conform run HOST --world URL can arrange an obstacle, a calibration failure, a sluggish joint, "
    "the panic button and, with --cougar sim, a silent wrist or a force on the hand.  Port 0 picks a free "
    "one; the line 'manip-server: world on URL' says which.",
)
@version_option(PROG)
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
    profile: str,
    error_args: ErrorArgs | None,
    async_layout: AsyncLayout | None,
    length_unit: LengthUnit | None,
    configuration_bits: ConfigurationBits | None,
    powered: bool,
    no_extensions: bool,
    max_clients: int,
    cougar: str | None,
    record: str | None,
    allow: AccessList,
    frame_timeout: float,
    link_idle_timeout: float,
    max_links: int,
    accept_backoff: float,
    show_stats: bool,
    log_level: str,
    world: str | None,
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
            cougar_host, _ = parse_drv11j_address(cougar)
        except ValueError as exc:
            raise click.BadParameter(str(exc), param_hint="--cougar") from None
        why = check_host(cougar_host)
        if why is not None:
            raise click.BadParameter(why, param_hint="--cougar")
    extra = [_address(url, "--chudp", "chudp") for url in chudp]
    if world is not None and not _address(world, "--world", "tcp").startswith("tcp://"):
        raise click.BadParameter(f"{world!r}: the world listens on tcp://HOST:PORT", param_hint="--world")
    limits = LinkLimits(
        frame_timeout=_off_if_zero(frame_timeout),
        idle_timeout=_off_if_zero(link_idle_timeout),
        max_links=max_links or None,
        accept_backoff=accept_backoff,
    )
    for url in [address, *extra]:
        warning = exposure_warning(parse_address(url), allow)
        if warning is not None:
            click.echo(warning, err=True)
    configure_logging(log_level)
    chosen = {
        "error_args": error_args,
        "async_layout": async_layout,
        "length_unit": length_unit,
        "configuration_bits": configuration_bits,
        "extensions": False if no_extensions else None,
    }
    config = server_config(
        profile,
        model=MODELS[model],
        powered_at_open=powered,
        faults=faults,
        **{name: value for name, value in chosen.items() if value is not None},
    )
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
        options=None if broken_after is None else NcpConfig.breaking_after(broken_after),
        limits=limits,
        allow=allow if allow.restricts_ip or allow.restricts_chaos else None,
    )
    recording = None
    if record is not None:
        recording = functools.partial(
            _recording, record, seed=seed, command_line=command_line(click.get_current_context())
        )
    try:
        asyncio.run(_run(server, contact, recording, show_stats=show_stats, world=world))
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
    *,
    show_stats: bool = False,
    world: str | None = None,
) -> None:
    """Run ``server()`` until SIGINT or SIGTERM, recording it with what ``recording()`` makes; print the
    stats line on SIGUSR1 and, with ``show_stats``, at exit; serve its world on ``world``."""
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
            if hasattr(signal, "SIGUSR1"):
                with contextlib.suppress(NotImplementedError):
                    loop.add_signal_handler(signal.SIGUSR1, lambda: print(stats_line(running), flush=True))
            try:
                async with _world(running, world):
                    await stop.wait()
            finally:
                if hasattr(signal, "SIGUSR1"):
                    loop.remove_signal_handler(signal.SIGUSR1)
            _report(running)
        if show_stats:  # after the close: the links it closed are counted
            print(stats_line(running), flush=True)
    finally:
        # After the server's close, so the CLS each connection got is in the file.
        if recorder is not None:
            recorder.close()
            _report_recording(recorder)
    if recorder is not None and recorder.write_error is not None:  # logged when it happened
        raise click.ClickException(str(recorder.write_error))


@contextlib.asynccontextmanager
async def _world(running: ReferenceServer, address: str | None) -> AsyncIterator[None]:
    """Serve the server's world on ``address`` (nothing when None), printing where."""
    if address is None:
        yield
        return
    async with serve_world(ReferenceWorld(running), address) as world:
        print(f"{PROG}: world on {world.address}", flush=True)
        yield


def _counts(counter: Counter[str]) -> str:
    total = sum(counter.values())
    parts = ", ".join(f"{key} {n}" for key, n in sorted(counter.items()) if n)
    return f"{total} ({parts})" if parts else str(total)


def stats_line(server: ReferenceServer) -> str:
    """One line of the server's link counters: what it accepted, refused, closed and dropped."""
    guards, links = server.link_stats()
    refused = guards.refused.copy()
    refused["busy"] += server.stats.refused
    return (
        f"{PROG}: stats: links accepted {guards.accepted}, refused {_counts(refused)}, "
        f"idle-closed {_counts(guards.idle_closed)}, over-limit {_counts(guards.over_limit)}, "
        f"accept errors {guards.accept_errors}, bad frames {_counts(links.bad)}"
    )


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
