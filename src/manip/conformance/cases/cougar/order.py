"""What one tick does and in which order (B.6 GUTS), gravity-corrected forces and the guards that test
them (B.8, B.9), NOP after an out-of-sync (Table 1, B.7), and a tick's burst of responses (§8.4 IDXS)."""

from __future__ import annotations

import math
from typing import Final

from manip.conformance.cases.cougar._support import (
    ALWAYS,
    clean,
    expect_names,
    expect_reply,
    expect_trips,
    guard_words,
    read_forces,
    settle,
)
from manip.conformance.cougar.probe import cougar_probe
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext
from manip.spec.constants import CougarCommand
from manip.spec.notation import octal

PHANTOM_OZ: Final = 64.0
"""Weight of an object Cougar is told of (NEWWC) that the hand does not hold."""
UNKNOWN_CODE: Final = 0o777
NOPS: Final = 3


@case("cougar.guts.order", clauses=["cougar.guts-order"], hazard="config")
async def guts_order(ctx: CaseContext) -> None:
    """GUARDM runs before COMINT in a tick: a guard that always trips, armed by a command read in one
    tick, is first tested, and trips, on the next."""
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        await probe.run(1)
        await probe.send_words(guard_words(5, tol=ALWAYS))
        first = await probe.run(1)
        expect_trips(
            ctx,
            first,
            [],
            clause="cougar.guts-order",
            expected="no trip in the tick that read GUARDS (GUARDM runs before COMINT)",
        )
        second = await probe.run(1)
        expect_trips(
            ctx,
            second,
            [("GUARD-CONTINUE", 5)],
            clause="cougar.guts-order",
            expected="guard 5 tripping on the next tick (GUARD-CONTINUE 5)",
        )


@case(
    "cougar.guard.gravity-corrected",
    clauses=["cougar.gravity", "cougar.guard-corrected-force", "cougar.rfrc.reply", "cougar.response.layout"],
    hazard="config",
)
async def gravity_corrected(ctx: CaseContext) -> None:
    """RFRC reports forces less the gravity load NEWWC describes: telling Cougar of an object the hand
    does not hold shows that object's weight; a guard along it stays quiet while the model is right
    and trips once NEWWC makes it wrong."""
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        await settle(probe)
        try:
            before = await read_forces(ctx, probe)
            await probe.send("NEWWC", weight=PHANTOM_OZ, cg=(0.0, 0.0, 0.0))
            await probe.run(2)
            after = await read_forces(ctx, probe)
            shift = [a - b for a, b in zip(after[:3], before[:3], strict=True)]
            size = math.sqrt(sum(v * v for v in shift))
            ctx.expect_near(
                size,
                PHANTOM_OZ,
                0.1 * PHANTOM_OZ,
                clause="cougar.gravity",
                expected=f"the force to move by the {PHANTOM_OZ:g} oz of the object NEWWC describes",
                seen=f"it moved by {size:.2f} oz: {before[:3]} -> {after[:3]}",
            )
            dvec = (*(v / size for v in shift), 0.0, 0.0, 0.0) if size else (0.0,) * 6
            await probe.send("NEWWC", weight=0.0, cg=(0.0, 0.0, 0.0))
            await probe.run(2)
            await probe.send_words(guard_words(9, dvec, PHANTOM_OZ / 2))
            quiet = await probe.run(3)
            expect_trips(
                ctx,
                quiet,
                [],
                clause="cougar.guard-corrected-force",
                expected="no trip while the gravity model matches the hand",
            )
            await probe.send("NEWWC", weight=PHANTOM_OZ, cg=(0.0, 0.0, 0.0))
            tripped = await probe.run(3)
            expect_trips(
                ctx,
                tripped,
                [("GUARD-CONTINUE", 9)],
                clause="cougar.guard-corrected-force",
                expected="guard 9 tripping once NEWWC adds an object the hand does not hold",
            )
        finally:
            await probe.send("NEWWC", weight=0.0, cg=(0.0, 0.0, 0.0))
            await clean(probe)


@case(
    "cougar.comint.nop-resync",
    clauses=[
        "cougar.nop-resync",
        "cougar.comint.unknown-code",
        "cougar.vers.reply",
        "cougar.response.layout",
    ],
    hazard="config",
)
async def nop_resync(ctx: CaseContext) -> None:
    """After an out-of-sync, NOPs answer nothing and the command after them is executed."""
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        await probe.send_words([UNKNOWN_CODE])
        got = await probe.run(2)
        expect_names(
            ctx,
            got,
            ["OUT-OF-SYNC"],
            clause="cougar.comint.unknown-code",
            expected=f"one OUT-OF-SYNC for the unknown code {octal(UNKNOWN_CODE)}",
        )
        await probe.send_words([CougarCommand.NOP] * NOPS + [CougarCommand.VERS, 1])
        got = await probe.run(2)
        expect_names(
            ctx,
            got,
            ["VERSION"],
            clause="cougar.nop-resync",
            expected=f"{NOPS} NOPs answered with nothing, then VERS answered with VERSION",
        )
        expect_reply(ctx, got[0], "VERSION", "cougar.vers.reply", after="VERS")


@case(
    "cougar.link.idxs-burst",
    clauses=["cougar.idxs-in-progress", "cougar.response.layout"],
    hazard="read-only",
)
async def idxs_burst(ctx: CaseContext) -> None:
    """Four commands in one tick draw four responses, every word once and in order (IDXS started only
    when it is not already sending)."""
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        await probe.send_words(
            [CougarCommand.RFRC, CougarCommand.VERS, 1, CougarCommand.RRAW, CougarCommand.RFRC]
        )
        got = await probe.run(2)
        asked = ["FORCES", "VERSION", "RAW", "FORCES"]
        expect_names(
            ctx,
            got,
            asked,
            clause="cougar.idxs-in-progress",
            expected=f"{', '.join(asked)}, in the order asked, nothing doubled",
        )
        ctx.expect(
            not any(r.problem for r in got),
            clause="cougar.idxs-in-progress",
            expected="each response of the burst whole",
            seen=got,
        )
