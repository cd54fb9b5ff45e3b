"""``manip-capture``: record a session through a transparent proxy, list a capture, recover a cut one.

    manip-capture record --listen tcp://127.0.0.1:42086 --upstream tcp://127.0.0.1:42085 -o s.mcap
    manip-capture info s.mcap
    manip-capture recover s.mcap [-o fixed.mcap]

``record`` prints ``manip-capture: recording tcp://HOST:PORT -> UPSTREAM into FILE`` on stdout once it
listens (the real port when 0 was asked for) and runs until SIGINT/SIGTERM or ``--seconds``; the file
is then finished.  Exit status: 0 done; 1 the file cannot be read, written or recovered, or the proxy
cannot listen; 2 usage error.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import signal
import sys

import click

from .listing import info_json, info_lines
from .proxy import Endpoint, parse_endpoint, start_proxy
from .reader import read_capture
from .recorder import COMPRESSIONS, DEFAULT_FLUSH_INTERVAL, CaptureError, Recorder
from .recover import recover as recover_file

__all__ = ["main"]


@click.group(context_settings={"help_option_names": ["-h", "--help"], "show_default": True})
@click.version_option(package_name="manip")
def main() -> None:
    """Record, list and recover manip session captures (MCAP; Foxglove opens them)."""


@main.command()
@click.option(
    "--listen",
    required=True,
    metavar="URL",
    help="Where clients connect: tcp://HOST:PORT or chudp://HOST:PORT.",
)
@click.option("--upstream", required=True, metavar="URL", help="The server, same scheme as --listen.")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="The capture to write.")
@click.option("--seconds", type=click.FloatRange(min=0.0), default=None, help="Stop after S seconds.")
@click.option(
    "--seed", type=int, default=None, help="Seed to note in the metadata (of the session recorded)."
)
@click.option("--compression", type=click.Choice(sorted(COMPRESSIONS)), default="zstd")
@click.option(
    "--flush-interval",
    type=click.FloatRange(min=0.01),
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
    "-o", "--output", type=click.Path(dir_okay=False), default=None, help="Default: CAPTURE.recovered.mcap."
)
def recover(capture: str, output: str | None) -> None:
    """Rebuild a valid capture from a truncated one (a killed recorder) and say what was lost."""
    try:
        report = recover_file(capture, output)
    except CaptureError as exc:
        click.echo(f"manip-capture: {exc}", err=True)
        sys.exit(1)
    click.echo(report.summary())


if __name__ == "__main__":
    main()
