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

from manip.conformance.cougar.probe import cougar_liveness
from manip.conformance.suite.case import Case, all_cases
from manip.conformance.suite.context import RunOptions
from manip.conformance.suite.results import RunReport
from manip.conformance.suite.runner import RunConfig, RunEvents, Runner
from manip.conformance.suite.selection import PatternSet
from manip.cougar.cli import CougarServer, serve_cougar
from manip.cougar.faults import parse_faults
from manip.cougar.link import parse_address
from manip.cougar.sim import CougarConfig, CougarSim

__all__ = ["EMBEDDED", "CougarTarget", "cougar_cases", "liveness_check", "run_cougar_suite", "wait_idle"]

EMBEDDED = "sim"
"""The ``--cougar`` value that starts the simulated Cougar in-process."""


@dataclass(frozen=True)
class CougarTarget:
    """Where the Cougar is (``sim`` or ``tcp://HOST:PORT``) and, for ``sim``, the faults it has."""

    url: str = EMBEDDED
    faults: frozenset[str] = field(default_factory=frozenset)

    @classmethod
    def parse(cls, url: str | None, faults: Iterable[str] = ()) -> CougarTarget:
        """ValueError for an address that is not ``sim`` or ``tcp://HOST[:PORT]``, for an unknown
        fault, or for faults asked of an external Cougar."""
        text = (url or EMBEDDED).strip()
        chosen = parse_faults(faults)
        if text != EMBEDDED:
            parse_address(text)
            if chosen:
                raise ValueError("--cougar-fault applies to the embedded Cougar only (--cougar sim)")
        return cls(text, chosen)

    @property
    def embedded(self) -> bool:
        return self.url == EMBEDDED

    @contextlib.asynccontextmanager
    async def running(self) -> AsyncIterator[str]:
        """The target's DRV-11J address for the block (the embedded Cougar serves only inside it)."""
        if not self.embedded:
            yield self.url
            return
        sim = CougarSim(CougarConfig(faults=self.faults), seed=0)
        async with serve_cougar(sim, "tcp://127.0.0.1:0") as server:
            yield server.address
            await wait_idle(server)

    def reproduce_prefix(self) -> tuple[str, ...]:
        """The start of a reproduce command (an external target's address is appended by the runner)."""
        faults = [w for f in sorted(self.faults) for w in ("--cougar-fault", f)]
        if self.embedded:
            return ("manip-conform", "run", "--cougar", EMBEDDED, *faults)
        return ("manip-conform", "run", "--cougar")


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
        config = RunConfig(
            address=address,
            options=replace(options or RunOptions(), address=address),
            seed=seed,
            select=PatternSet.of(select, "select"),
            embedded=target.embedded,
            reproduce_prefix=target.reproduce_prefix(),
            liveness_check=liveness_check,
        )
        return await Runner(config, cougar_cases(all_cases(), cougar=True), events).run()
