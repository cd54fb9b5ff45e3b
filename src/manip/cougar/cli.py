"""``manip-cougar``: serve a simulated Cougar over the emulated DRV-11J (``docs/drv11j.md``).

    manip-cougar --listen tcp://127.0.0.1:42011 [--seed N] [--surface PX,PY,PZ[,NX,NY,NZ[,K]]] ...
    manip-cougar --print-memory-map [--cougar-reading relocated-map]

Once listening it prints ``manip-cougar: listening on tcp://HOST:PORT`` (the real port when 0 was asked
for) and serves until interrupted.  One Cougar serves one Puma at a time, as the cable allowed: a second
connection while one is open gets HELLO then BYE "busy".  The simulated Cougar keeps its state (offsets,
guards, memory) across connections, as the real one did across Puma sessions; it runs only when the
Puma's ticks arrive.

:func:`serve_cougar` is the asyncio driver behind the command, usable with any Cougar model.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import sys
from collections.abc import AsyncIterator
from typing import Final

import click

from manip.commandline import check_host, configure_logging, version_option
from manip.cougar.environment import Contacts, Spring, Surface
from manip.cougar.faults import CougarFault, link_defects, parse_faults
from manip.cougar.link import CougarEnd, CougarModel, Drv11jError, parse_drv11j_address
from manip.cougar.memory_map import memory_map_toml
from manip.cougar.readings import READINGS, parse_readings
from manip.cougar.sim import CougarConfig, CougarSim
from manip.exit_status import epilog

__all__ = ["CougarServer", "main", "parse_surface", "serve_cougar"]

log = logging.getLogger("manip.cougar")
BUSY: Final = "busy: this Cougar is serving another Puma"
_READ: Final = 1 << 16


class CougarServer:
    """A listening Cougar (from :func:`serve_cougar`); ``address`` has the real port."""

    def __init__(self, model: CougarModel, faults: frozenset[str] = frozenset()) -> None:
        self.model = model
        self.defects = link_defects(faults)
        """The link's defects (:mod:`manip.cougar.faults`, ``link-*``), for testing conformance suites."""
        self.connections = 0
        self.busy = False
        self.server: asyncio.Server | None = None
        self.address = ""
        self.last_time: float | None = None
        """The model's time at the last tick of any link: the next link's clock continues from it."""

    async def _handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        end = CougarEnd(self.model, resume_after=self.last_time, defects=self.defects)
        writer.write(end.hello())
        if self.busy and self.defects.refuses_second_puma:
            writer.write(end.bye(BUSY))
            await _close(writer)
            return
        self.busy = True
        self.connections += 1
        peer = writer.get_extra_info("peername")
        log.info("Puma connected from %s", peer)
        try:
            while end.closed is None:
                data = await reader.read(_READ)
                if not data:
                    break
                try:
                    out = end.receive(data)
                except Drv11jError as exc:
                    writer.write(end.bye(str(exc)))
                    break
                if out:
                    writer.write(out)
                    await writer.drain()
        except (ConnectionError, OSError) as exc:
            log.info("link from %s broke: %s", peer, exc)
        except asyncio.CancelledError:
            # Shutdown with a Puma still linked.  Ending quietly: Python 3.11's stream server asks a
            # cancelled handler task for its exception and logs the CancelledError as a traceback.
            log.info("link from %s closed at shutdown", peer)
        finally:
            self.last_time = end.last_time
            self.busy = False
            log.info("Puma %s gone (%s); %d ticks", peer, end.closed or "EOF", end.ticks)
            await _close(writer)


async def _close(writer: asyncio.StreamWriter) -> None:
    writer.close()
    with contextlib.suppress(Exception):
        await writer.wait_closed()


@contextlib.asynccontextmanager
async def serve_cougar(
    model: CougarModel, address: str, *, faults: frozenset[str] = frozenset()
) -> AsyncIterator[CougarServer]:
    """Serve ``model`` on ``address`` (``tcp://HOST:PORT``, port 0 for a free one) for the block; the
    link has the defects ``faults`` names (``link-*`` of :mod:`manip.cougar.faults`; none by default)."""
    host, port = parse_drv11j_address(address)
    cougar = CougarServer(model, faults)
    server = await asyncio.start_server(cougar._handle, host, port)
    cougar.server = server
    sock_host, sock_port = server.sockets[0].getsockname()[:2]
    shown = f"[{sock_host}]" if ":" in sock_host else sock_host
    cougar.address = f"tcp://{shown}:{sock_port}"
    try:
        async with server:
            yield cougar
    finally:
        server.close()


def parse_surface(text: str) -> tuple[tuple[float, float, float], tuple[float, float, float], float | None]:
    """``PX,PY,PZ[,NX,NY,NZ[,K]]`` -> point (mm), normal (default +z), stiffness (oz/mm, None = default)."""
    try:
        v = [float(x) for x in text.split(",")]
    except ValueError:
        raise click.BadParameter(f"{text!r}: numbers separated by commas expected") from None
    if not all(math.isfinite(x) for x in v):
        raise click.BadParameter(f"{text!r}: every number must be finite")
    if len(v) not in (3, 6, 7):
        raise click.BadParameter(f"{text!r}: 3, 6 or 7 numbers expected (point, normal, stiffness)")
    normal = (v[3], v[4], v[5]) if len(v) >= 6 else (0.0, 0.0, 1.0)
    return (v[0], v[1], v[2]), normal, (v[6] if len(v) == 7 else None)


def _make_model(
    seed: int | None,
    surfaces: tuple[str, ...],
    springs: tuple[str, ...],
    faults: frozenset[str] = frozenset(),
    readings: frozenset[str] = frozenset(),
) -> CougarModel:
    parts: list[Surface | Spring] = []
    for text in surfaces:
        point, normal, stiffness = parse_surface(text)
        parts.append(Surface(point, normal) if stiffness is None else Surface(point, normal, stiffness))
    for text in springs:
        point, _, stiffness = parse_surface(text)
        parts.append(Spring(point) if stiffness is None else Spring(point, stiffness))
    environment = Contacts(tuple(parts)) if parts else None
    config = CougarConfig(faults=faults, readings=readings)
    sim: CougarModel = CougarSim(config, environment=environment, seed=seed)
    return sim


async def _serve_forever(model: CougarModel, address: str, faults: frozenset[str]) -> None:
    async with serve_cougar(model, address, faults=faults) as cougar:
        print(f"manip-cougar: listening on {cougar.address}", flush=True)
        await asyncio.Event().wait()


@click.command(context_settings={"help_option_names": ["-h", "--help"]}, epilog=epilog("manip-cougar"))
@click.option(
    "--listen",
    "address",
    default="tcp://127.0.0.1:42011",
    show_default=True,
    help="Where to listen.",
)
@click.option("--seed", type=int, default=None, help="Seed of the simulator's noise.")
@click.option(
    "--surface",
    "surfaces",
    multiple=True,
    metavar="PX,PY,PZ[,NX,NY,NZ[,K]]",
    help="A plane the tool can press on: a point (mm), its outward normal (default +z), stiffness (oz/mm).",
)
@click.option(
    "--spring",
    "springs",
    multiple=True,
    metavar="AX,AY,AZ[,_,_,_,K]",
    help="A spring from the tool point to an anchor (mm), stiffness K (oz/mm).",
)
@click.option(
    "--cougar-fault",
    "faults",
    multiple=True,
    type=click.Choice(sorted(f.value for f in CougarFault)),
    help="Simulate a protocol defect (to check a conformance suite catches it); repeatable.",
)
@click.option(
    "--cougar-reading",
    "readings",
    multiple=True,
    type=click.Choice(sorted(READINGS)),
    help="Take another reading of the 1985 guide, one a conformance suite must accept (docs/drv11j.md); "
    "repeatable.",
)
@click.option(
    "--print-memory-map",
    is_flag=True,
    help="Print this Cougar's memory map (with the readings given) in the format of manip-conform's "
    "--memory-map, and exit.",
)
@click.option("-v", "--verbose", is_flag=True, help="Log connections.")
@version_option("manip-cougar")
def main(
    address: str,
    seed: int | None,
    surfaces: tuple[str, ...],
    springs: tuple[str, ...],
    faults: tuple[str, ...],
    readings: tuple[str, ...],
    print_memory_map: bool,
    verbose: bool,
) -> None:
    """Serve a simulated Cougar wrist computer over the emulated DRV-11J link."""
    if print_memory_map:
        shift = CougarConfig(readings=parse_readings(readings)).map_shift
        click.echo(memory_map_toml(shift), nl=False)
        return
    configure_logging(logging.INFO if verbose else logging.WARNING)
    try:
        host, _port = parse_drv11j_address(address)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--listen") from None
    why = check_host(host)
    if why is not None:
        raise click.BadParameter(why, param_hint="--listen")
    model = _make_model(seed, surfaces, springs, parse_faults(faults), parse_readings(readings))
    try:
        with contextlib.suppress(KeyboardInterrupt):
            asyncio.run(_serve_forever(model, address, parse_faults(faults)))
    except OSError as exc:  # the port is taken, the socket path cannot be made...
        click.echo(f"manip-cougar: cannot listen on {address}: {exc.strerror or exc}", err=True)
        sys.exit(1)
