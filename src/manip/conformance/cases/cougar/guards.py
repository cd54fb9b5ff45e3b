"""Guards (GUARDS, GUARDC): a guard trips once, clears, and trips on its condition."""

from __future__ import annotations

from typing import Final

from manip.conformance.cases.cougar._support import (
    NEVER,
    STOP_BIT,
    clean,
    expect_none,
    expect_trips,
    guard_trips,
    guard_words,
    others,
    read_forces,
    settle,
)
from manip.conformance.cougar.probe import (
    cougar_probe,
)
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext

HIGH_BYTE_LOW_BIT: Final = 0x0100
"""Bit 8 of a guard's type word: in the high byte (B.9) but not the 'hi bit' (Table 1); either type."""
TINY_TOL: Final = 2.0**-127
"""A tolerance just above 0 that a PDP-11 float holds."""


# ------------------------------------------------------------------------------------------ guards
@case(
    "cougar.guard.trips-once",
    clauses=["cougar.guards", "cougar.guard-trips-once"],
    hazard="config",
)
async def guard_trips_once(ctx: CaseContext) -> None:
    """A guard whose condition always holds trips exactly once: response 6 with its index when bit 15
    of the type word is set, 7 when its high byte is clear (bits 4-7 ignored); with bit 8 alone either
    (Table 1's 'hi bit' and B.9's 'high byte' differ there: erratum guard-type-bit); a guard that cannot
    trip stays silent; re-armed, it trips once more.  Each guard is its own check."""
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        await probe.send_words(guard_words(STOP_BIT | 0x0070 | 3))
        await probe.send_words(guard_words(0x00F0 | 12))
        await probe.send_words(guard_words(HIGH_BYTE_LOW_BIT | 5))
        await probe.send_words(guard_words(7, tol=NEVER))
        got = await probe.run(8)
        trips = guard_trips(got)
        for index, allowed, why in (
            (3, ("GUARD-STOP",), "bit 15 set"),
            (12, ("GUARD-CONTINUE",), "high byte clear, bits 4-7 set"),
            (
                5,
                ("GUARD-STOP", "GUARD-CONTINUE"),
                "bit 8 alone: stop by B.9's high byte, continue by Table 1's hi bit",
            ),
        ):
            mine = [name for name, i in trips if i == index]
            ctx.expect(
                len(mine) == 1,
                clause="cougar.guard-trips-once",
                expected=f"exactly one trip of guard {index} in 8 ticks",
                seen=got,
            )
            ctx.expect(
                all(name in allowed for name in mine),
                clause="cougar.guards",
                expected=f"guard {index} ({why}) reported with {' or '.join(allowed)}",
                seen=got,
            )
        ctx.expect(
            not [i for _, i in trips if i not in (3, 12, 5)],
            clause="cougar.guard-trips-once",
            expected="no trip of guard 7 (tolerance never reached) nor of any guard not armed",
            seen=got,
        )
        expect_none(ctx, others(got), "cougar.guards", "only guard responses")
        await probe.send_words(guard_words(STOP_BIT | 3))
        got = await probe.run(6)
        expect_trips(
            ctx,
            got,
            [("GUARD-STOP", 3)],
            clause="cougar.guard-trips-once",
            expected="guard 3, armed again, trips once more (one GUARD-STOP 3)",
        )
        await probe.send("GUARDC", index=7)
        await probe.run(1)


@case("cougar.guard.threshold", clauses=["cougar.guard-trip-threshold"], hazard="config")
async def guard_threshold(ctx: CaseContext) -> None:
    """A guard trips when the dot product passes tol and not before: with a zero dvec the dot product is
    exactly 0 whatever the force, so tol -2^-127 trips and tol 2^-127 does not.  A dot product equal to
    tol is not judged: 'tol = scalar to test' (Table 1) allows both (erratum guard-trip-comparison)."""
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        await probe.send_words(guard_words(2, tol=-TINY_TOL))
        await probe.send_words(guard_words(6, tol=TINY_TOL))
        got = await probe.run(6)
        trips = guard_trips(got)
        ctx.expect(
            [t for t in trips if t[1] == 2] == [("GUARD-CONTINUE", 2)],
            clause="cougar.guard-trip-threshold",
            expected="guard 2 (dot 0 above tol -2^-127) trips once, as GUARD-CONTINUE",
            seen=got,
        )
        ctx.expect(
            not [t for t in trips if t[1] != 2],
            clause="cougar.guard-trip-threshold",
            expected="guard 6 (tol 2^-127 above the dot product 0) never trips",
            seen=got,
        )
        await probe.send("GUARDC", index=6)
        await probe.run(1)


@case(
    "cougar.guard.clear",
    clauses=["cougar.guardc", "cougar.guards"],
    hazard="config",
)
async def guard_clear(ctx: CaseContext) -> None:
    """GUARDC disarms a guard before it trips; the guard armed with it and not cleared still trips."""
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        await probe.send_words(guard_words(5))
        await probe.send_words(guard_words(9))
        await probe.send("GUARDC", index=5)
        got = await probe.run(8)
        trips = guard_trips(got)
        ctx.expect(
            not [t for t in trips if t[1] == 5],
            clause="cougar.guardc",
            expected="guard 5 cleared in the same tick it was armed never trips",
            seen=got,
        )
        ctx.expect(
            [t for t in trips if t[1] != 5] == [("GUARD-CONTINUE", 9)],
            clause="cougar.guardc",
            expected="guard 9, armed with it and not cleared, trips once (GUARD-CONTINUE 9)",
            seen=got,
        )


@case(
    "cougar.guard.condition",
    clauses=["cougar.guards", "cougar.response.layout", "cougar.rfrc.reply"],
    hazard="config",
)
async def guard_condition(ctx: CaseContext) -> None:
    """A guard trips when the dot product of the force with its dvec exceeds tol, not otherwise (both
    signs of dvec, tolerances just below and above the force Cougar reports)."""
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        await settle(probe)
        force = await read_forces(ctx, probe)
        axis = max(range(3), key=lambda i: abs(force[i]))
        f = force[axis]
        margin = max(2.0, 0.05 * abs(f))
        unit = tuple(1.0 if i == axis else 0.0 for i in range(6))
        minus = tuple(-x for x in unit)
        guards = {  # index: (dvec, tol, trips)
            1: (unit, f - margin, True),
            2: (unit, f + margin, False),
            3: (minus, -f - margin, True),
            4: (minus, -f + margin, False),
        }
        for index, (dvec, tol, _) in guards.items():
            await probe.send_words(guard_words(index, dvec, tol))
        got = await probe.run(6)
        trips = guard_trips(got)
        for index, (dvec, tol, should) in guards.items():  # each guard its own check
            mine = [t for t in trips if t[1] == index]
            dot = f * dvec[axis]
            ctx.expect(
                mine == ([("GUARD-CONTINUE", index)] if should else []),
                clause="cougar.guards",
                expected=f"guard {index} (dot {dot:.4g} {'>' if should else '<'} tol {tol:.4g}, "
                f"force[{axis}] = {f:.4g}): {'one GUARD-CONTINUE' if should else 'no trip'}",
                seen=got,
            )
        await clean(probe)
