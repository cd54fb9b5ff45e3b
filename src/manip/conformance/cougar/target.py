"""The Cougar target of ``manip-conform run --cougar URL``: what the runner needs besides the cases.

``--cougar tcp://HOST:PORT`` checks a Cougar already listening on the emulated DRV-11J (``manip-cougar``
or a third party's); ``--cougar sim`` starts the simulated Cougar in-process on a free loopback port for
the run (optionally with ``--cougar-fault`` defects, for proving the suite).  In this mode only cases of
target ``cougar`` (ids ``cougar.*``) run, each over its own DRV-11J link
(:mod:`manip.conformance.cougar.probe`), and the liveness probe is a HELLO and one tick instead of a
Chaos request.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

from manip.conformance.cougar.probe import cougar_liveness
from manip.conformance.suite.case import Case, all_cases
from manip.conformance.suite.context import RunOptions
from manip.conformance.suite.results import RunReport
from manip.conformance.suite.runner import RunConfig, RunEvents, Runner
from manip.conformance.suite.selection import PatternSet
from manip.cougar.cli import CougarServer, serve_cougar
from manip.cougar.faults import parse_faults
from manip.cougar.link import parse_drv11j_address
from manip.cougar.memory_map import CougarMemoryMap, load_memory_map, own_map
from manip.cougar.readings import parse_readings
from manip.cougar.sim import CougarConfig, CougarSim

__all__ = ["EMBEDDED", "CougarTarget", "cougar_cases", "liveness_check", "run_cougar_suite", "wait_idle"]

EMBEDDED = "sim"
"""The ``--cougar`` value that starts the simulated Cougar in-process."""


@dataclass(frozen=True)
class CougarTarget:
    """Where the Cougar is (``sim`` or ``tcp://HOST:PORT``), for ``sim`` the faults it has and the
    readings it takes, and the memory map declared for it (``--memory-map``)."""

    url: str = EMBEDDED
    faults: frozenset[str] = field(default_factory=frozenset)
    readings: frozenset[str] = field(default_factory=frozenset)
    memory_map: CougarMemoryMap | None = None
    map_path: Path | None = None

    @classmethod
    def parse(
        cls,
        url: str | None,
        faults: Iterable[str] = (),
        readings: Iterable[str] = (),
        memory_map: Path | None = None,
    ) -> CougarTarget:
        """ValueError for an address that is not ``sim`` or ``tcp://HOST[:PORT]``, for an unknown
        fault or reading, for either asked of an external Cougar, or for a memory map file that cannot
        be used (:class:`~manip.cougar.memory_map.MemoryMapError` says why)."""
        text = (url or EMBEDDED).strip()
        chosen = parse_faults(faults)
        taken = parse_readings(readings)
        if text != EMBEDDED:
            parse_drv11j_address(text)
            if chosen:
                raise ValueError("--cougar-fault applies to the embedded Cougar only (--cougar sim)")
            if taken:
                raise ValueError("--cougar-reading applies to the embedded Cougar only (--cougar sim)")
        declared = load_memory_map(memory_map) if memory_map is not None else None
        return cls(text, chosen, taken, declared, memory_map)

    def declared_map(self) -> CougarMemoryMap | None:
        """The map the cases use: the one declared (``--memory-map``); for the embedded Cougar without
        one, its own (relocated with it); for another Cougar without one, none."""
        if self.memory_map is not None or not self.embedded:
            return self.memory_map
        return own_map(self.config().map_shift)

    def config(self) -> CougarConfig:
        """The embedded Cougar's configuration."""
        return CougarConfig(faults=self.faults, readings=self.readings)

    @property
    def embedded(self) -> bool:
        return self.url == EMBEDDED

    @contextlib.asynccontextmanager
    async def running(self) -> AsyncIterator[str]:
        """The target's DRV-11J address for the block (the embedded Cougar serves only inside it)."""
        if not self.embedded:
            yield self.url
            return
        sim = CougarSim(self.config(), seed=0)
        async with serve_cougar(sim, "tcp://127.0.0.1:0", faults=sim.config.faults) as server:
            yield server.address
            await wait_idle(server)

    def reproduce_prefix(self) -> tuple[str, ...]:
        """The start of a reproduce command (an external target's address is appended by the runner)."""
        faults = [w for f in sorted(self.faults) for w in ("--cougar-fault", f)]
        faults += [w for r in sorted(self.readings) for w in ("--cougar-reading", r)]
        faults += ["--memory-map", str(self.map_path)] if self.map_path is not None else []
        if self.embedded:
            return ("manip-conform", "run", "--cougar", EMBEDDED, *faults)
        return ("manip-conform", "run", *faults, "--cougar")


async def wait_idle(server: CougarServer, timeout: float = 1.0) -> None:
    """Let the last link's handler finish closing before ``server`` stops (on Python 3.11 a handler
    cancelled in the middle of its close is logged by asyncio as an error)."""
    loop = asyncio.get_running_loop()
    give_up = loop.time() + timeout
    while server.busy and loop.time() < give_up:
        await asyncio.sleep(0.01)
    await asyncio.sleep(0.02)


def cougar_cases(cases: Sequence[Case], *, cougar: bool) -> list[Case]:
    """The cases of a Cougar run (target ``cougar``: ids ``cougar.*``) or of a server run (``server.*``)."""
    return [c for c in cases if c.target == ("cougar" if cougar else "server")]


async def liveness_check(options: RunOptions) -> tuple[bool, str]:
    """The runner's liveness probe for a Cougar target (``RunConfig.liveness_check``)."""
    return await cougar_liveness(
        options.address, reply_timeout=options.reply_timeout, connect_timeout=options.connect_timeout
    )


async def run_cougar_suite(
    target: CougarTarget,
    *,
    seed: int = 0,
    select: Iterable[str] = (),
    options: RunOptions | None = None,
    events: RunEvents | None = None,
) -> RunReport:
    """Run the Cougar cases (those matching ``select``, all when empty) against ``target``: what
    ``manip-conform run --cougar`` does, without the console and the files."""
    async with target.running() as address:
        options = options or RunOptions()
        config = RunConfig(
            options=replace(
                options,
                address=address,
                embedded=target.embedded,
                cougar_map=options.cougar_map or target.declared_map(),
            ),
            seed=seed,
            select=PatternSet.of(select, "select"),
            reproduce_prefix=target.reproduce_prefix(),
            liveness_check=liveness_check,
        )
        return await Runner(config, cougar_cases(all_cases(), cougar=True), events).run()
