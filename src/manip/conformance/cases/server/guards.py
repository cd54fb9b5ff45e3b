"""A wrist guard hit end to end (E.3 Opcode 203; Part III B.9): the guard-hit response, what a stopping
guard does to the motion, and nothing the client did not ask for.

The guard is made to trip on the wrist's own gravity load: Cougar's guards test the gravity-corrected
force (B.8, B.9), so telling it of an object the hand does not hold (set weight) leaves exactly that
object's weight in the corrected force, pointing the way gravity does in hand coordinates.  A guard
along that force with half its size as tolerance trips on the next tick, whatever the arm's pose, and
rotating joint 1 (about the vertical) does not turn gravity in the hand's frame."""

from __future__ import annotations

import math
from typing import Final

from manip.conformance.cases._support import (
    expect_refusal,
    no_wrist,
    power_on,
    read_floats,
    require_response,
    settle,
)
from manip.conformance.cases.server.wrist import steady_forces
from manip.conformance.judge.checks import WirePacket, async_of
from manip.conformance.judge.violation import missing
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext, Probe
from manip.conformance.suite.world import WristForce
from manip.spec.constants import AsyncCondition, ServerOp

PHANTOM_OZ: Final = 64.0
"""The weight of the object Cougar is told of, which the hand does not hold (ounces)."""
PHANTOM_TOL_OZ: Final = 8.0
"""How far the corrected force may be from the phantom weight (the gravity model's rounding, the
gauges' noise); pounds, 16 times too small, are far outside."""
STOP_BIT: Final = 0x8000
GUARD_BIT: Final = 1 << 0
"""request-notifications mask bit of guard hits (bit n = condition n+1)."""
SWING_DEG: Final = 40.0
"""How far joint 1 is asked to turn: long enough that a guard trips while the arm moves."""
HIT_WAIT: Final = 2.0
"""Seconds to wait for a guard hit after arming a guard that trips on the next tick."""
QUIET: Final = 0.5
"""Seconds to watch for unrequested packets."""


async def _guard_hit(ctx: CaseContext, probe: Probe, wait: float) -> WirePacket | None:
    """The next guard-hit response within ``wait`` seconds (other packets are kept in the recording)."""
    deadline = ctx.clock() + wait
    while (left := deadline - ctx.clock()) > 0:
        packet = await probe.next_packet(left)
        if packet is None:
            return None
        message = async_of(packet) if packet.opcode == ServerOp.ASYNCHRONOUS_RESPONSE else None
        if message is not None and message.condition == AsyncCondition.GUARD_HIT:
            return packet
    return None


def _swing(start: tuple[float, ...]) -> list[float]:
    goal = list(start)
    goal[0] += SWING_DEG if goal[0] <= 0 else -SWING_DEG
    return goal


def _unrequested(probe: Probe, mask: int, since: float) -> list[WirePacket]:
    """Asynchronous responses since ``since`` whose condition the mask did not ask for."""
    return [
        p
        for p in probe.packets
        if p.direction == "s2c"
        and p.time >= since
        and p.opcode == ServerOp.ASYNCHRONOUS_RESPONSE
        and not mask >> ((_condition(p) or 1) - 1) & 1
    ]


def _condition(packet: WirePacket) -> int | None:
    message = async_of(packet)
    return None if message is None else message.condition


@case(
    "server.async.guard-hit",
    clauses=["async.layout", "async.codes", "async.only-when-requested", "motion.abort", "read-forces.units"],
    hazard="motion",
    deadline=20.0,
    extensions=[
        "wrist-version",
        "set-gauge-offsets",
        "set-frame-vector",
        "set-weight",
        "read-forces",
        "set-guard",
        "request-notifications",
        "reset-abort",
    ],
)
async def guard_hit(ctx: CaseContext) -> None:
    """A guard that trips during a move is reported as asked: code 1, word 2 = 1 (stopped) or 2 (goes
    on), word 3 = the guard; a stopping guard aborts the motion (AWA until reset), a continuing one does
    not; with guard hits not asked for, nothing is sent.

    It needs a wrist computer (the wrist opcodes, Puma extensions, served): against a server without one
    it is not judged (the embedded server has the simulated Cougar; a manip-server gets one with --cougar
    sim)."""
    probe = await ctx.connect()
    version = await probe.call("wrist-version")
    if not version.is_response:
        ctx.not_judged(no_wrist(version))
    await power_on(ctx, probe)
    start = await read_floats(ctx, probe, "joint-angles")
    # Cougar's settings outlive a connection (erratum cougar-connection-state): start from none, so the
    # gauges' 16-bit arithmetic stays where a weight shows at its size.
    require_response(ctx, await probe.call("set-gauge-offsets", offsets=[0] * 8), "zero gauge offsets")
    require_response(ctx, await probe.call("set-frame-vector", offset=[0.0] * 3), "no frame vector")
    require_response(ctx, await probe.call("set-weight", weight=0.0, cg=[0.0] * 3), "no weight")
    rest = await steady_forces(ctx, probe, "at rest, with no offsets, frame vector or weight")
    require_response(ctx, await probe.call("set-weight", weight=PHANTOM_OZ, cg=[0.0, 0.0, 0.0]), "set weight")
    try:
        forces = await steady_forces(ctx, probe, "after set weight")
        change = math.dist(forces[:3], rest[:3])
        ctx.expect_near(
            change,
            PHANTOM_OZ,
            PHANTOM_TOL_OZ,
            clause="read-forces.units",
            expected=f"the corrected force changed by {PHANTOM_OZ:g} oz after set weight of a "
            f"{PHANTOM_OZ:g} oz object the hand does not hold (ounces)",
            seen=f"changed by {change:.2f}, from {[round(f, 2) for f in rest]} to "
            f"{[round(f, 2) for f in forces]}",
        )
        size = math.sqrt(sum(f * f for f in forces[:3]))
        if size < PHANTOM_OZ / 4:
            ctx.not_judged(
                f"the wrist's corrected force did not follow set weight ({size:.1f} oz for a "
                f"{PHANTOM_OZ:g} oz object the hand does not hold): no load to trip a guard on"
            )
        dvec = [f / size for f in forces[:3]] + [0.0, 0.0, 0.0]
        tol = size / 2
        await _stopping(ctx, probe, start, dvec, tol)
        await _continuing(ctx, probe, start, dvec, tol)
        await _unasked(ctx, probe, dvec, tol)
    finally:
        await probe.call("set-weight", weight=0.0, cg=[0.0, 0.0, 0.0])
        await power_on(ctx, probe)
        await probe.call("set-joint-angles", joints=list(start))
        await settle(ctx, probe, start, within=5.0)


async def _stopping(
    ctx: CaseContext, probe: Probe, start: tuple[float, ...], dvec: list[float], tol: float
) -> None:
    """A stop-the-move guard: hit reported with word 2 = 1, the motion aborted, motion refused AWA."""
    index = ctx.random.randrange(16)
    since = ctx.clock()
    require_response(ctx, await probe.call("request-notifications", mask=GUARD_BIT), "guard notifications")
    require_response(ctx, await probe.call("set-joint-angles", joints=_swing(start)), "a move of joint 1")
    require_response(ctx, await probe.call("set-joint-angles", joints=list(start)), "a move back")
    require_response(
        ctx,
        await probe.call("set-guard", type_index=STOP_BIT | index, dvec=dvec, tol=tol),
        "a stop-the-move guard",
    )
    await _expect_stop(
        ctx,
        probe,
        index,
        after=f"arming guard {index} across a {2 * tol:.1f} oz load",
        then=_swing(start),
        what="a move after a stop-the-move guard aborted the motion",
    )
    await probe.drain(QUIET)
    extra = _unrequested(probe, GUARD_BIT, since)
    only = "no segment-completed responses (only guard hits asked for)"
    ctx.expect_none(extra, clause="async.only-when-requested", expected=only)


async def _continuing(
    ctx: CaseContext, probe: Probe, start: tuple[float, ...], dvec: list[float], tol: float
) -> None:
    """A continue guard: hit reported with word 2 = 2, and the move goes on to its goal."""
    require_response(ctx, await probe.call("reset-abort"), "reset abort")
    here = await read_floats(ctx, probe, "joint-angles")
    index = ctx.random.randrange(16)
    goal = _swing(start) if abs(here[0] - start[0]) < SWING_DEG / 2 else list(start)
    require_response(ctx, await probe.call("set-joint-angles", joints=goal), "a move of joint 1")
    require_response(
        ctx, await probe.call("set-guard", type_index=index, dvec=dvec, tol=tol), "a continue guard"
    )
    await _expect_hit(ctx, probe, index, after=f"arming continue guard {index}", stops=False)
    ctx.expect(
        await settle(ctx, probe, goal, within=5.0) is not None,
        clause="motion.abort",
        expected="the move to end at its goal after a continue guard (nothing aborted)",
        seen="the arm stopped short of it",
    )


async def _unasked(ctx: CaseContext, probe: Probe, dvec: list[float], tol: float) -> None:
    """With guard hits not asked for, a continue guard's trip sends nothing."""
    require_response(ctx, await probe.call("request-notifications", mask=0), "no notifications")
    since = ctx.clock()
    index = ctx.random.randrange(16)
    require_response(
        ctx, await probe.call("set-guard", type_index=index, dvec=dvec, tol=tol), "a continue guard"
    )
    await probe.call("wrist-version")
    await probe.drain(QUIET)
    extra = _unrequested(probe, 0, since)
    ctx.expect_none(
        extra,
        clause="async.only-when-requested",
        expected="no asynchronous response for a guard hit not asked for",
    )


PUSH_OZ: Final = 48.0
"""The force the world puts on the hand to trip the live guard (ounces, along the hand's x axis)."""
SETTLE_S: Final = 5.0
STEADY_OZ: Final = 1.0
"""The wrist's reading at rest is steady once it moves less than this in a quarter second (ounces)."""
PUSH_TOL_OZ: Final = 24.0
"""The live guard's tolerance above what the wrist reads at rest: half the push."""


async def _steady_x(ctx: CaseContext, probe: Probe) -> float:
    """The force the wrist reads along the hand's x axis at rest, once it holds still (a gauge offset
    another case set reaches the forces through Cougar's filter, over a few ticks)."""
    last = (await read_floats(ctx, probe, "read-forces"))[0]
    deadline = ctx.clock() + SETTLE_S
    while ctx.clock() < deadline:
        await probe.drain(0.25)
        now = (await read_floats(ctx, probe, "read-forces"))[0]
        if abs(now - last) < STEADY_OZ:
            return now
        last = now
    ctx.not_judged(f"the wrist's reading along x did not hold still at rest within {SETTLE_S:g} s")


@case(
    "server.async.guard-trip-live",
    clauses=["async.layout", "async.codes", "motion.abort"],
    hazard="motion",
    deadline=20.0,
    extensions=[
        "wrist-version",
        "clear-guard",
        "set-gauge-offsets",
        "set-frame-vector",
        "set-weight",
        "read-forces",
        "set-guard",
        "request-notifications",
    ],
)
async def guard_trip_live(ctx: CaseContext) -> None:
    """A stop-the-move guard armed across the hand's x axis does not trip at rest, and trips when the
    world pushes the hand along it: a guard-hit response (code 1, word 2 = 1, word 3 = the guard), and
    the motion aborted (AWA until reset).

    The target's world puts the force on the hand (``wrist-force``: the embedded server's world always,
    another target's with ``--world``); without a world the case is not judged, nor on a target that
    serves no wrist."""
    probe = await ctx.connect()
    version = await probe.call("wrist-version")
    if not version.is_response:
        ctx.not_judged(no_wrist(version))
    await power_on(ctx, probe)
    for other in range(16):  # guards other cases left armed would trip too
        await probe.call("clear-guard", index=other)
    # Offsets, frame vector and weight other cases left (property cases send any) can push the
    # gauges' 16-bit arithmetic past where a push shows: start from none.
    require_response(ctx, await probe.call("set-gauge-offsets", offsets=[0] * 8), "zero gauge offsets")
    require_response(ctx, await probe.call("set-frame-vector", offset=[0.0] * 3), "no frame vector")
    require_response(ctx, await probe.call("set-weight", weight=0.0, cg=[0.0] * 3), "no weight")
    start = await read_floats(ctx, probe, "joint-angles")
    rest = await _steady_x(ctx, probe)
    tol = rest + PUSH_TOL_OZ  # what the wrist reads at rest (offsets other cases left) and a margin
    index = ctx.random.randrange(16)
    require_response(ctx, await probe.call("request-notifications", mask=GUARD_BIT), "guard notifications")
    dvec = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    require_response(
        ctx,
        await probe.call("set-guard", type_index=STOP_BIT | index, dvec=dvec, tol=tol),
        "a stop-the-move guard",
    )
    early = await _guard_hit(ctx, probe, QUIET)
    ctx.expect(
        early is None,
        clause="async.codes",
        expected=f"no guard hit while nothing pushes the hand (guard {index}, {PUSH_TOL_OZ:g} oz above rest)",
        seen=early,
    )
    for goal in (_swing(start), list(start), _swing(start), list(start)):  # moving when the push comes
        require_response(ctx, await probe.call("set-joint-angles", joints=goal), "a move of joint 1")
    try:
        async with ctx.arranged(WristForce((PUSH_OZ, 0.0, 0.0))):
            await _expect_stop(
                ctx,
                probe,
                index,
                after=f"a {PUSH_OZ:g} oz push across guard {index}",
                then=list(start),
                what="a move after the pushed guard stopped the motion",
            )
    finally:
        await probe.call("clear-guard", index=index)
        await power_on(ctx, probe)
        await probe.call("set-joint-angles", joints=list(start))
        await settle(ctx, probe, start, within=5.0)


async def _expect_stop(
    ctx: CaseContext, probe: Probe, index: int, *, after: str, then: list[float], what: str
) -> None:
    """Guard ``index`` (a stop-the-move guard) is reported tripped with its number (``after``: what
    should trip it), and the move ``then`` is refused as aborted (``what``)."""
    await _expect_hit(ctx, probe, index, after=after, stops=True)
    refused = await probe.call("set-joint-angles", joints=then)
    expect_refusal(ctx, refused, clause="motion.abort", severities=("E",), codes=("AWA",), what=what)


async def _expect_hit(ctx: CaseContext, probe: Probe, index: int, *, after: str, stops: bool) -> None:
    """A guard-hit response for guard ``index`` within :data:`HIT_WAIT` of ``after``, saying the
    trajectory stopped (``stops``) or continues."""
    hit = await _guard_hit(ctx, probe, HIT_WAIT)
    if hit is None:
        ctx.fail(
            f"no guard-hit response within {HIT_WAIT:g} s of {after}",
            clause="async.codes",
            expected="an asynchronous response (203) with condition code 1 (guard hit)",
            seen=missing("nothing"),
        )
    kind, said = (1, "trajectory stopped") if stops else (2, "trajectory continues")
    message = async_of(hit)
    ctx.expect(
        message is not None and (message.word2, message.word3) == (kind, index),
        clause="async.layout",
        expected=f"word 2 = {kind} ({said}), word 3 = {index} (the guard)",
        seen=hit,
    )
