"""``manip-capture``: record a session through a transparent proxy, list a capture, recover a cut one.

    manip-capture record --listen tcp://127.0.0.1:42086 --upstream tcp://127.0.0.1:42085 -o s.mcap
    manip-capture info s.mcap
    manip-capture recover s.mcap [-o fixed.mcap]
    manip-capture import session.pcap -o session.mcap [--port 42042] [--server HOST:PORT]
    manip-capture export s.mcap -o s.pcapng

``record`` prints ``manip-capture: recording tcp://HOST:PORT -> UPSTREAM into FILE`` on stdout once it
listens (the real port when 0 was asked for) and runs until SIGINT/SIGTERM or ``--seconds``; the file
is then finished.  Exit status (:mod:`manip.exit_status`): 0 done; 1 the file cannot be read, written,
recovered, imported or exported, or the proxy cannot listen; 2 usage error, a file to read that does not
exist.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import signal
import sys

import click

from manip.commandline import FiniteFloat, check_host, configure_logging, version_option
from manip.exit_status import epilog

from .listing import info_json, info_lines
from .pcap import CHUDP_PORT, export_pcapng, import_pcap, parse_host_port
from .proxy import Endpoint, parse_endpoint, start_proxy
from .reader import read_capture
from .recorder import COMPRESSIONS, DEFAULT_FLUSH_INTERVAL, CaptureError, Recorder
from .recover import recover as recover_file

__all__ = ["main"]


@click.group(
    context_settings={"help_option_names": ["-h", "--help"], "show_default": True},
    epilog=epilog("manip-capture"),
)
@version_option("manip-capture")
def main() -> None:
    """Record, list and recover manip session captures (MCAP; Foxglove opens them)."""
    configure_logging()


@main.command()
@click.option(
    "--listen",
    required=True,
    metavar="URL",
    help="Where clients connect: tcp://HOST:PORT or chudp://HOST:PORT.",
)
@click.option(
    "--upstream",
    required=True,
    metavar="URL",
    help="The server, same scheme as --listen.",
)
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="The capture to write.")
@click.option("--seconds", type=FiniteFloat(min=0.0), default=None, help="Stop after S seconds.")
@click.option(
    "--seed", type=int, default=None, help="Seed to note in the metadata (of the session recorded)."
)
@click.option("--compression", type=click.Choice(sorted(COMPRESSIONS)), default="zstd")
@click.option(
    "--flush-interval",
    type=FiniteFloat(min=0.01),
    default=DEFAULT_FLUSH_INTERVAL,
    help="Seconds between chunk flushes.",
)
@click.option("--no-view", is_flag=True, help="Raw frames only (no decoded JSON view).")
def record(
    listen: str,
    upstream: str,
    output: str,
    seconds: float | None,
    seed: int | None,
    compression: str,
    flush_interval: float,
    no_view: bool,
) -> None:
    """Record every frame between clients and a server, as a transparent proxy."""
    try:
        listen_end, upstream_end = parse_endpoint(listen), parse_endpoint(upstream)
    except CaptureError as exc:
        raise click.BadParameter(str(exc)) from None
    for option, end in (("--listen", listen_end), ("--upstream", upstream_end)):
        why = check_host(end.host)
        if why is not None:
            raise click.BadParameter(why, param_hint=option)
    if listen_end.scheme != upstream_end.scheme:  # refuse before the capture file is created
        schemes = f"{listen_end.scheme}:// to {upstream_end.scheme}://"
        raise click.UsageError(f"cannot proxy {schemes}: use the same link on both sides")
    try:
        asyncio.run(
            _record(listen_end, upstream_end, output, seconds, seed, compression, flush_interval, not no_view)
        )
    except CaptureError as exc:
        click.echo(f"manip-capture: {exc}", err=True)
        sys.exit(1)


async def _record(
    listen: Endpoint,
    upstream: Endpoint,
    output: str,
    seconds: float | None,
    seed: int | None,
    compression: str,
    flush_interval: float,
    view: bool,
) -> None:
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError):
            loop.add_signal_handler(sig, stop.set)
    with Recorder(
        output,
        how=f"proxy {listen.scheme}",
        seed=seed,
        decoded_view=view,
        compression=compression,
        flush_interval=flush_interval,
    ) as recorder:
        proxy, bound = await start_proxy(recorder, listen, upstream)
        click.echo(f"manip-capture: recording {bound} -> {upstream} into {output}")
        sys.stdout.flush()
        try:
            if seconds is None:
                await stop.wait()
            else:
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(stop.wait(), seconds)
        finally:
            await proxy.aclose()
        click.echo(
            f"manip-capture: {recorder.counts['/chaos/c2s'] + recorder.counts['/chaos/s2c']} frames, "
            f"{recorder.connections} connection(s) recorded"
        )
    if recorder.write_error is not None:  # a full disk: the file is cut short, and says so when read
        raise recorder.write_error


@main.command()
@click.argument("capture", type=click.Path(exists=True, dir_okay=False))
@click.option("--packets/--no-packets", default=True, help="List every packet.")
@click.option("--json", "as_json", is_flag=True, help="One JSON document (each packet as its decoded view).")
def info(capture: str, packets: bool, as_json: bool) -> None:
    """List a capture: metadata, channels, time span, links, sessions, one line per packet."""
    try:
        cap = read_capture(capture)
    except CaptureError as exc:
        click.echo(f"manip-capture: {exc}", err=True)
        sys.exit(1)
    if as_json:
        click.echo(json.dumps(info_json(cap, packets=packets), indent=1))
        return
    for line in info_lines(cap, packets=packets):
        click.echo(line)


@main.command()
@click.argument("capture", type=click.Path(exists=True, dir_okay=False))
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False),
    default=None,
    help="Default: the capture's name with .mcap replaced by .recovered.mcap (s.mcap -> s.recovered.mcap).",
)
def recover(capture: str, output: str | None) -> None:
    """Rebuild a valid capture from a truncated one (a killed recorder) and say what was lost."""
    try:
        report = recover_file(capture, output)
    except CaptureError as exc:
        click.echo(f"manip-capture: {exc}", err=True)
        sys.exit(1)
    click.echo(report.summary())


def _address(ctx: click.Context, param: click.Parameter, value: str | None) -> tuple[str, int] | None:
    if value is None:
        return None
    try:
        return parse_host_port(value)
    except ValueError as exc:
        raise click.BadParameter(str(exc)) from None


@main.command("import")
@click.argument("pcap", metavar="FILE.pcap", type=click.Path(exists=True, dir_okay=False))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="The capture to write.")
@click.option(
    "--port",
    "ports",
    type=click.IntRange(0, 65535),
    multiple=True,
    help=f"Only UDP datagrams from or to this port (repeatable; CHUDP's is {CHUDP_PORT}). "
    "Default: every UDP datagram that starts like CHUDP.",
)
@click.option(
    "--server",
    metavar="HOST:PORT",
    callback=_address,
    default=None,
    help="The server's address (default: the side that receives the RFC).",
)
def import_(pcap: str, output: str, ports: tuple[int, ...], server: tuple[str, int] | None) -> None:
    """Turn the CHUDP traffic of a tcpdump or Wireshark capture (pcap, pcapng) into a manip capture.

    One UDP address pair is one link; manip-conform verify and replay accept the result.
    """
    try:
        report = import_pcap(pcap, output, ports=ports, server=server)
    except CaptureError as exc:
        click.echo(f"manip-capture: {exc}", err=True)
        sys.exit(1)
    click.echo(report.summary())
    if not report.frames:
        click.echo(f"manip-capture: no CHUDP datagrams in {pcap}", err=True)
        sys.exit(1)


@main.command("export")
@click.argument("capture", metavar="FILE.mcap", type=click.Path(exists=True, dir_okay=False))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="The pcapng to write.")
def export(capture: str, output: str) -> None:
    """Write a manip capture as CHUDP in UDP/IPv4 (pcapng), for Wireshark and tshark.

    TCP-link sessions are re-framed as CHUDP; the file's comment says so.
    """
    try:
        report = export_pcapng(capture, output)
    except CaptureError as exc:
        click.echo(f"manip-capture: {exc}", err=True)
        sys.exit(1)
    click.echo(report.summary())


if __name__ == "__main__":
    main()
