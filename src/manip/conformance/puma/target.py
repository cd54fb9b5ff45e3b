"""The Puma target of ``manip-conform run --puma [HOST]``: a Puma server judged from its wrist side.

The suite plays Cougar (:class:`~manip.conformance.puma.judge.JudgingCougar`) and drives the Puma through
its Chaos side; only cases of target ``puma`` (ids ``puma.*``) run.  Three set-ups:

* **No HOST, virtual time** (the default): the reference server runs on the run's virtual-clock loop,
  its wrist processes wired to the judge through the DRV-11J frame codec in-process
  (:class:`~manip.conformance.puma.judge.FramedPort`): the same seed gives the same verdict.
* **No HOST, ``--time real``**: the judge listens on a free loopback ``tcp://`` port, as ``manip-cougar``
  does, and the reference server runs on its own thread with ``--cougar`` pointed at it.
* **HOST**: the judge listens on ``--wrist-listen`` (``tcp://127.0.0.1:42011``, manip-cougar's port, by
  default) and waits for the Puma's DRV-11J link, so the Puma under test is started after the suite
  with its wrist pointed there (``manip-server --cougar tcp://127.0.0.1:42011``); HOST is its Chaos
  address.

The embedded server's world (:class:`~manip.conformance.suite.embedded.EmbeddedWorld`) arranges what
the cases ask of it: ``puma.compliance.no-collision-test`` needs an obstacle in joint 1's way above
:data:`OBSTACLE_FROM` degrees, into which a compliant move may push while a plain one collides.  Against
HOST the run's ``--world`` arranges it (contract 2, ``docs/world-harness.md``).
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import random
import tempfile
from collections.abc import AsyncIterator, Callable, Iterable, Sequence
from dataclasses import dataclass, replace
from typing import Final

from manip.conformance.puma.judge import FramedPort, JudgingCougar, judging
from manip.conformance.suite.case import Case, all_cases
from manip.conformance.suite.context import RunOptions
from manip.conformance.suite.embedded import EmbeddedServer, ServerEnvironment
from manip.conformance.suite.results import RunReport
from manip.conformance.suite.runner import RunConfig, RunEvents, Runner
from manip.conformance.suite.selection import PatternSet
from manip.conformance.suite.world import World
from manip.cougar.cli import serve_cougar
from manip.cougar.link import DEFAULT_PORT, parse_drv11j_address
from manip.reference_server import FaultSet, ServerConfig
from manip.reference_server.cougar_wrist import CougarWrist
from manip.reference_server.driver import serve

__all__ = [
    "DEFAULT_WRIST_LISTEN",
    "DEFAULT_WRIST_WAIT",
    "OBSTACLE_FROM",
    "OBSTACLE_JOINT",
    "PumaTarget",
    "PumaUnreachableError",
    "puma_cases",
    "run_puma_suite",
]

DEFAULT_WRIST_LISTEN: Final = f"tcp://127.0.0.1:{DEFAULT_PORT}"
DEFAULT_WRIST_WAIT: Final = 60.0
"""Seconds the judge waits for an external Puma's DRV-11J link."""
OBSTACLE_JOINT: Final = 1
OBSTACLE_FROM: Final = 60.0
"""The embedded robot's obstacle: joint 1 cannot pass this angle (degrees)."""


class PumaUnreachableError(ConnectionError):
    """The Puma under test never opened its wrist link to the judge."""


@dataclass(frozen=True)
class PumaTarget:
    """Where the Puma is (``host`` None: the embedded reference server) and where its wrist is judged."""

    host: str | None = None
    wrist_listen: str = DEFAULT_WRIST_LISTEN
    wrist_wait: float = DEFAULT_WRIST_WAIT
    faults: tuple[str, ...] = ()
    """The embedded server's fault switches (``NAME[=ARG]``)."""
    virtual: bool = True

    def __post_init__(self) -> None:
        parse_drv11j_address(self.wrist_listen)  # ValueError for a bad address
        if self.host is not None and self.faults:
            raise ValueError("fault switches apply to the embedded server only (omit HOST)")
        self.server_config()  # ValueError for a bad fault

    @property
    def embedded(self) -> bool:
        return self.host is None

    def server_config(self) -> ServerConfig:
        """The embedded server's configuration: the faults asked for."""
        return ServerConfig(faults=FaultSet.parse(self.faults))

    @contextlib.asynccontextmanager
    async def running(self, seed: int, judge: JudgingCougar | None = None) -> AsyncIterator[str]:
        """The Puma's Chaos address for the block, with the judge serving its wrist."""
        async with self.running_with_world(seed, judge) as (address, _):
            yield address

    @contextlib.asynccontextmanager
    async def running_with_world(
        self, seed: int, judge: JudgingCougar | None = None
    ) -> AsyncIterator[tuple[str, World | None]]:
        """:meth:`running`, with the embedded server's world (None for HOST, whose world is the run's)."""
        judge = judge or JudgingCougar(seed)
        with judging(judge):
            if self.host is None and self.virtual:
                async with _virtual_server(self.server_config(), judge, seed) as served:
                    yield served
                return
            listen = self.wrist_listen if self.host is not None else "tcp://127.0.0.1:0"
            async with serve_cougar(judge, listen) as cougar:
                if self.host is None:
                    config = self.server_config()
                    embedded = EmbeddedServer(config, wrist=True, cougar=cougar.address, seed=seed)
                    with embedded as address:
                        await _wait_link(lambda: cougar.connections, self.wrist_wait)
                        assert embedded.environment is not None
                        yield address, embedded.environment.world
                    return
                await _wait_link(lambda: cougar.connections, self.wrist_wait)
                yield self.host, None

    def reproduce_prefix(self) -> tuple[str, ...]:
        if self.host is None:
            return ("manip-conform", "run", "--puma")
        return ("manip-conform", "run", "--puma", "--wrist-listen", self.wrist_listen)


async def _wait_link(links: Callable[[], int], timeout: float) -> None:
    """Until the Puma has opened its DRV-11J link to the judge (PumaUnreachableError after ``timeout``)."""
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout
    while not links():
        if loop.time() >= end:
            raise PumaUnreachableError(
                f"the Puma opened no wrist link to the judging Cougar within {timeout:g} s"
            )
        await asyncio.sleep(0.01)


@contextlib.asynccontextmanager
async def _virtual_server(
    config: ServerConfig, judge: JudgingCougar, seed: int
) -> AsyncIterator[tuple[str, World]]:
    """The reference server on this (virtual-clock) loop, its wrist wired to ``judge`` in-process; its
    address and its world."""
    random.seed(seed)  # connection indices come from it: part of the simulated world

    def wrist() -> CougarWrist:
        return CougarWrist(FramedPort(judge))

    with tempfile.TemporaryDirectory(prefix="manip-puma-") as directory:
        path = os.path.join(directory, "puma.sock")
        async with serve(f"unix://{path}", config, seed=seed, wrist_factory=wrist) as server:
            yield server.address, ServerEnvironment(server).world


def puma_cases(cases: Sequence[Case]) -> list[Case]:
    """The cases of a Puma run (target ``puma``)."""
    return [c for c in cases if c.target == "puma"]


async def run_puma_suite(
    target: PumaTarget,
    *,
    seed: int = 0,
    select: Iterable[str] = (),
    options: RunOptions | None = None,
    events: RunEvents | None = None,
) -> RunReport:
    """Run the Puma cases (those matching ``select``, all when empty) against ``target``: what
    ``manip-conform run --puma`` does, without the console and the files (call it on a virtual-clock
    loop for a virtual-time target)."""
    async with target.running_with_world(seed) as (address, world):
        config = RunConfig(
            options=replace(options or RunOptions(), address=address, embedded=target.embedded),
            seed=seed,
            select=PatternSet.of(select, "select"),
            virtual_time=target.embedded and target.virtual,
            reproduce_prefix=target.reproduce_prefix(),
            world=world,
        )
        return await Runner(config, puma_cases(all_cases()), events).run()
