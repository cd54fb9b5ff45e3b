"""The two sides of a diff, and what one side showed of one stream (the I/O of the diff).

A side is an address (a server someone runs; driven in real time) or the embedded reference server
(with its simulated Cougar wrist and its world, as ``manip-conform run``'s embedded target) with its
configuration (a :class:`~manip.reference_server.ServerConfig`: fault switches, the guide
profile, the error-argument layout).  An embedded side runs in virtual time
(:func:`manip.conformance.suite.embedded.simulated_server` on a
:class:`~manip.links.virtual_clock.VirtualClockLoop`): a fresh server for every stream, seeded from
the diff's seed, so the same stream gives the same bytes every time and a motion costs no wall time.
An addressed side gets a fresh connection (and fresh links) for every stream.

A stream is sent by the fuzzer's batch runner (:class:`~manip.conformance.fuzz.batch.BatchRunner`: one
hand-driven Chaos connection, every read bounded by the reply and connect timeouts), followed by its
liveness check, and judged by the fuzzer's judges (:func:`~manip.conformance.fuzz.judge.judge`).  A
side that does not finish a stream within :func:`stream_bound` ends it: a *runaway*, judged as a hang.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Final

from manip.arm.units import LengthUnit
from manip.conformance.diff.oracles import arg_value_sightings
from manip.conformance.diff.pairing import SideEvent, events_of
from manip.conformance.diff.streams import Stream
from manip.conformance.fuzz.batch import BatchRunner, liveness
from manip.conformance.fuzz.generators import LinkKind
from manip.conformance.fuzz.judge import Sighting, judge
from manip.conformance.fuzz.session import Allowance
from manip.conformance.fuzz.steps import Silence
from manip.conformance.judge.violation import Violation
from manip.conformance.suite.embedded import SimulatedLink, simulated_environment
from manip.conformance.suite.world import Condition, ConditionUnsupported, World, WorldError
from manip.conformance.suite.world_link import open_world
from manip.links import LinkAddress, parse_address, virtual_clock
from manip.reference_server import ServerConfig

__all__ = ["Observation", "Side", "input_link", "observe", "reachable", "stream_bound"]

BOUND_BASE: Final = 30.0
BOUND_PER_INPUT: Final = 20.0
"""Seconds (virtual ones for an embedded side) a stream may take: the base and per input."""


def stream_bound(stream: Stream, allowance: Allowance) -> float:
    """How long a side may take over ``stream`` before it is a runaway (its silences on top)."""
    per = max(BOUND_PER_INPUT, 4 * allowance.reply)
    silent = sum(s.seconds for i in stream.all_inputs for s in i.steps if isinstance(s, Silence))
    return BOUND_BASE + per * len(stream.all_inputs) + silent


def input_link(link: SimulatedLink) -> LinkKind:
    """The link whose inputs the generated streams draw for embedded sides reached over ``link``: the
    datagram link's for CHUDP, the stream link's for the Unix socket and chaosd (whose raw frames in
    manip's TCP link framing the chaosd daemon stand-in, not the server, takes: it closes the link)."""
    return "datagram" if link == "chudp" else "stream"


@dataclass(frozen=True)
class Side:
    """Side ``name`` (A or B): at ``address``, or the embedded server with ``config``; ``words``: how
    the command line named it (for reproduce lines)."""

    name: str
    label: str
    address: LinkAddress | None = None
    config: ServerConfig | None = None
    words: tuple[str, ...] = ()
    world: str | None = None
    """An addressed side's world (``--world-a/-b``: tcp://HOST:PORT or a command, contract 2)."""
    unit: LengthUnit = "mm"
    """An addressed side's length unit, as the command line declares it (nothing on the wire says it)."""
    link: SimulatedLink = "unix"
    """How an embedded side is reached (``--link``): a Unix socket with the TCP link framing, CHUDP, or
    usim's chaosd framing through a routing daemon stand-in."""
    broken_after: float | None = None
    """The side's broken-connection timer in seconds (``--broken-after``; erratum ncp-timers): an
    embedded server is given it, an addressed side is declared to use it.  None: not known, and the
    scenarios that wait it out are not sent."""

    @property
    def embedded(self) -> bool:
        return self.config is not None

    @property
    def length_unit(self) -> LengthUnit:
        """The unit of lengths on the side's wire (erratum units): an embedded server's own."""
        return self.config.length_unit if self.config is not None else self.unit


@dataclass
class Observation:
    """What one side showed of one stream: its events by input, the judges' sightings, a runaway."""

    events: dict[int, list[SideEvent]] = field(default_factory=dict)
    sightings: list[Sighting] = field(default_factory=list)
    runaway: str | None = None
    seconds: float = 0.0
    unarranged: str | None = None
    """Why the stream was not sent: a condition of the arm's world it needs was not arranged."""
    unjudged: list[str] = field(default_factory=list)
    """What the scenario's check could not judge on this side, and why (never a finding)."""


def observe(side: Side, stream: Stream, allowance: Allowance, seed: int) -> Observation:
    """Send ``stream`` to ``side`` and gather what it showed (module docstring)."""
    if side.config is not None:
        config = side.config

        async def embedded() -> Observation:
            async with simulated_environment(
                config, seed=seed, wrist=True, link=side.link, broken_after=side.broken_after
            ) as env:
                arranged = await _arranged(env.world, stream.conditions)
                if isinstance(arranged, str):
                    return Observation(unarranged=arranged)
                async with arranged:
                    return await _observe(parse_address(env.address), stream, allowance, seed, env.world)

        return virtual_clock.run(embedded(), virtual=True)
    assert side.address is not None
    address = side.address
    if not stream.needs:
        return asyncio.run(_observe(address, stream, allowance, seed))
    if side.world is None:
        needs = ", ".join(c.describe() for c in stream.needs)
        return Observation(
            unarranged=f"it needs {needs}, and side {side.name} has no --world-{side.name.lower()}"
        )

    async def with_world(spec: str) -> Observation:
        try:
            async with open_world(spec, answer_timeout=allowance.connect) as world:
                arranged = await _arranged(world, stream.conditions)
                if isinstance(arranged, str):
                    return Observation(unarranged=arranged)
                async with arranged:
                    return await _observe(address, stream, allowance, seed, world)
        except WorldError as exc:
            return Observation(unarranged=f"side {side.name}'s world failed: {exc}")

    return asyncio.run(with_world(side.world))


async def _arranged(world: World, conditions: Sequence[Condition]) -> contextlib.AsyncExitStack | str:
    """An exit stack holding every condition arranged (leave it to clear them), or why one could not
    be."""
    stack = contextlib.AsyncExitStack()
    try:
        for condition in conditions:
            await stack.enter_async_context(world.arranged(condition))
    except (ConditionUnsupported, WorldError) as exc:
        await stack.aclose()
        return f"{world.description} cannot arrange it: {exc}"
    return stack


class _Phases:
    """A stream's phased conditions (:class:`~manip.conformance.diff.streams.WorldPhase`) on one side's
    world: before each input where the conditions that hold change, those that end are cleared and
    those that begin arranged; whatever holds at the end is cleared by :meth:`aclose`."""

    def __init__(self, world: World | None, stream: Stream) -> None:
        self.world = world
        self.held: dict[Condition, contextlib.AsyncExitStack] = {}
        self.changes: dict[int, Callable[[], Awaitable[None]]] = {}
        before: frozenset[Condition] = frozenset()
        for item in stream.inputs:
            wanted = frozenset(p.condition for p in stream.phases if item.number in p.inputs)
            if wanted != before:
                self.changes[item.number] = functools.partial(self._to, wanted)
            before = wanted

    async def _to(self, wanted: frozenset[Condition]) -> None:
        for condition in [c for c in self.held if c not in wanted]:
            await self.held.pop(condition).aclose()
        for condition in wanted - set(self.held):
            assert self.world is not None  # a stream with phases is sent only to a side with a world
            stack = contextlib.AsyncExitStack()
            await stack.enter_async_context(self.world.arranged(condition))
            self.held[condition] = stack

    async def aclose(self) -> None:
        await self._to(frozenset())


async def _observe(
    address: LinkAddress, stream: Stream, allowance: Allowance, seed: int, world: World | None = None
) -> Observation:
    loop = asyncio.get_running_loop()
    started = loop.time()
    phases = _Phases(world, stream)
    runner = BatchRunner(address, allowance, seed=seed, changes=phases.changes)
    bound = stream_bound(stream, allowance)
    try:
        try:
            async with asyncio.timeout(bound):
                run = await runner.run(stream.all_inputs)
                live = await liveness(runner)
        except (ConditionUnsupported, WorldError) as exc:  # a phase's condition, mid-stream
            whose = world.description if world is not None else "the side's world"
            return Observation(unarranged=f"{whose} cannot arrange it: {exc}")
        except TimeoutError:
            last = stream.all_inputs[-1].number
            why = f"the side did not finish the stream within {bound:g} s"
            hang = Sighting(Violation(why, None, "MUST", "the stream ended", why, kind="timeout"), last)
            event = SideEvent("stream", text=f"runaway: {why}")
            return Observation({last: [event]}, [hang], why, loop.time() - started)
        sightings = [_opening(s, stream) for s in judge(run, runner.inbox, live)]
        events = events_of(run, runner.inbox)
        for item in stream.all_inputs:
            sightings += arg_value_sightings(item, events.get(item.number, ()))
        if stream.check is not None:
            sightings += stream.check(events)
        unjudged: list[str] = []
        if stream.judge is not None:
            found, unjudged = stream.judge(events)
            sightings += found
        return Observation(events, sightings, None, loop.time() - started, unjudged=unjudged)
    finally:
        with contextlib.suppress(Exception):
            runner.close()
        await phases.aclose()


def _opening(sighting: Sighting, stream: Stream) -> Sighting:
    """A finding about how the connection opened (``connect.*`` with no packet to place it: the initial
    response never came), placed on the stream's first input, which opened it."""
    violation = sighting.violation
    if violation.packet is None and (violation.clause or "").startswith("connect."):
        return replace(sighting, number=stream.all_inputs[0].number)
    return sighting


def reachable(side: Side, allowance: Allowance, seed: int) -> str | None:
    """None when an addressed side takes a connection and answers Here; else why not."""
    if side.address is None:
        return None
    address = side.address

    async def check() -> str | None:
        runner = BatchRunner(address, allowance, seed=seed)
        try:
            live = await liveness(runner)
        finally:
            runner.close()
        return None if live.alive else live.detail

    return asyncio.run(check())
