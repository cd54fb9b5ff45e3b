"""The conformance suite run against a reference server in the same event loop: the one shared way for
tests of cases and of the runner (a server started on a free loopback port, the run, the server
stopped), rather than a ``serve`` and ``Runner`` of their own in every module.

:func:`run_on_reference_server` is the ``async`` form; :func:`run_suite` runs it in a fresh event loop,
and the ``reference_run`` fixture (``tests/conformance/conftest.py``) hands :func:`run_suite` to a test.
:func:`run_simulated` runs the cases as the embedded target is run (the simulated Cougar wrist and the
world included) in virtual time: a verdict that times the arm then never depends on the machine's load.
"""

from __future__ import annotations

import asyncio
from collections.abc import Mapping, Sequence
from typing import Any

from manip.conformance.suite.case import Case
from manip.conformance.suite.context import RunOptions
from manip.conformance.suite.embedded import ServerEnvironment, simulated_environment
from manip.conformance.suite.results import RunReport
from manip.conformance.suite.runner import RunConfig, Runner
from manip.links import virtual_clock
from manip.links.address import DEFAULT_SERVER_ADDR
from manip.reference_server import ServerConfig
from manip.reference_server.driver import serve
from tests.support.chaosd_router import chaosd_router
from tests.support.servers import LINK_ADDRESSES


async def run_on_reference_server(
    cases: Sequence[Case],
    server: ServerConfig | None = None,
    *,
    seed: int,
    time_scale: float = 1.0,
    options: Mapping[str, Any] | None = None,
    world: bool = False,
    **config: Any,
) -> RunReport:
    """Run ``cases`` against a reference server set up by ``server`` (faults, power...), started for the
    run on a free TCP port with ``time_scale`` and stopped after it.

    ``options`` are the :class:`RunOptions` besides the address (which is the server's); ``world``
    gives the run the server's world (its :class:`ServerEnvironment`'s), as the embedded target has; the other
    keywords are :class:`RunConfig` fields (``select``...)."""
    async with serve(LINK_ADDRESSES["tcp"], server, time_scale=time_scale) as reference:
        run_options = RunOptions(address=reference.address, **(options or {}))
        if world:
            config["world"] = ServerEnvironment(reference).world
        run_config = RunConfig(options=run_options, seed=seed, **config)
        return await Runner(run_config, cases).run()


def run_suite(cases: Sequence[Case], server: ServerConfig | None = None, **keywords: Any) -> RunReport:
    """:func:`run_on_reference_server` in an event loop of its own, for a synchronous test."""
    return asyncio.run(run_on_reference_server(cases, server, **keywords))


def run_simulated(
    cases: Sequence[Case],
    server: ServerConfig | None = None,
    *,
    seed: int,
    options: Mapping[str, Any] | None = None,
    broken_after: float | None = None,
    **config: Any,
) -> RunReport:
    """Run ``cases`` against the embedded target set up by ``server``, in virtual time, as
    ``manip-conform run`` does without a target: the reference server with the simulated Cougar wrist, on
    a Unix-domain socket in this loop, and its world.  ``broken_after`` is the server's broken-connection
    timer (default 90 s); ``options`` and the other keywords as for :func:`run_on_reference_server`."""

    async def main() -> RunReport:
        async with simulated_environment(
            server, seed=seed, wrist=True, broken_after=broken_after
        ) as environment:
            address = environment.address
            run_options = RunOptions(address=address, embedded=True, **(options or {}))
            run_config = RunConfig(
                options=run_options,
                seed=seed,
                world=environment.world,
                virtual_time=True,
                **config,
            )
            return await Runner(run_config, cases).run()

    return virtual_clock.run(main(), virtual=True)


LINK_OPTIONS = {"reply_timeout": 1.0, "connect_timeout": 1.0}
"""Run options of a run over a real link: a loopback answer takes well under a millisecond; a frame the
link refuses costs this much per wait."""


def run_over_link(
    cases: Sequence[Case], scheme: str, server: ServerConfig | None = None, *, seed: int
) -> RunReport:
    """Run ``cases`` against a reference server reached over a ``scheme`` link (``chudp``, or ``chaosd``
    through a routing stand-in for the daemon), in real time in this process: what the embedded run's
    Unix socket cannot show, the frames of those links."""

    async def main() -> RunReport:
        if scheme == "chaosd":
            # The server at the default address, as in the embedded run.
            async with chaosd_router() as (path, router), serve(f"chaosd://{path}", server):
                await router.name_silent(DEFAULT_SERVER_ADDR)
                return await _run(f"chaosd://{path}")
        async with serve(LINK_ADDRESSES[scheme], server) as reference:
            return await _run(reference.address)

    async def _run(address: str) -> RunReport:
        config = RunConfig(options=RunOptions(address=address, **LINK_OPTIONS), seed=seed)
        return await Runner(config, cases).run()

    return asyncio.run(main())
