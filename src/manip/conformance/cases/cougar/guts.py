"""JACOB's front buffer and GUTS, once per tick and never nested (cougar.guts-reentry)."""

from __future__ import annotations

from typing import Final

from manip.arm import READY
from manip.conformance.cases.cougar._support import (
    POSE_B,
    clean,
    expect_examined,
    expect_names,
    mapped,
)
from manip.conformance.cougar.probe import (
    cougar_probe,
    words_bytes,
)
from manip.conformance.judge.violation import showing
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext

# ------------------------------------------------------------------------------------------ JACOB, GUTS
LOOKS: Final = 40
"""Ticks the front buffer is looked at after the arm moves (a look a tick, the first in SEN's tick)."""


@case(
    "cougar.jacob.front-buffer-complete",
    clauses=["cougar.jacob-double-buffer", "cougar.memory", "cougar.exmn.reply", "cougar.response.layout"],
    hazard="config",
)
async def jacob_front_buffer(ctx: CaseContext) -> None:
    """After the arm moves, every tick's front Jacobian buffer is the old Jacobian or the new one,
    never a mixture; the new one arrives within a few ticks.  Each tick's look is one snapshot: the three
    EXMNs (which buffer is in front, and both buffers' J) go in one tick, and COMINT runs them together."""
    front, *buffers = mapped(ctx, "jacob_front", "jbuf0", "jbuf1")
    j_words = 2 * 36

    async def front_j() -> tuple[int, ...]:
        asked = ((front.address, 1), *((b.address, j_words) for b in buffers))
        for address, count in asked:
            await probe.send("EXMN", address=address, count=count)
        which, *both = [await expect_examined(ctx, probe, address, count) for address, count in asked]
        return both[which[0] & 1] if which else ()

    async with cougar_probe(ctx) as probe:
        await clean(probe)
        await probe.send("SEN", theta_sensed=READY)
        await probe.run(5)
        old = await front_j()
        await probe.send("SEN", theta_sensed=POSE_B)
        seen = [await front_j() for _ in range(LOOKS)]  # one tick each
        new = seen[-1]
        ctx.expect(
            new != old,
            clause="cougar.jacob-double-buffer",
            expected=f"a new Jacobian in the front buffer within {LOOKS - 1} ticks of SEN to a new pose",
            seen="unchanged",
        )
        ctx.expect(
            seen[-3:] == [new] * 3,
            clause="cougar.jacob-double-buffer",
            expected=f"the front buffer's Jacobian steady from {LOOKS - 3} ticks after SEN to a new pose",
            seen=f"still changing after {LOOKS - 3} ticks",
        )
        mixed = [i for i, j in enumerate(seen) if j not in (old, new)]
        ctx.expect(
            not mixed,
            clause="cougar.jacob-double-buffer",
            expected="the front buffer always the old or the new Jacobian",
            seen=showing(
                words_bytes(seen[mixed[0]]) if mixed else b"",
                f"another one at tick(s) {mixed} after the move",
            ),
        )
        await probe.send("SEN", theta_sensed=READY)
        await probe.run(1)


REENTRY_GAP_S: Final = 1e-6
"""A tick this soon after the previous one (the TICK frame's resolution) finds any GUTS still running."""


@case("cougar.guts.no-nesting", clauses=["cougar.guts-reentry"])
async def guts_no_nesting(ctx: CaseContext) -> None:
    """A tick one microsecond after the previous one either runs a whole GUTS (one GUTS per TICK,
    docs/drv11j.md) or finds GUTS still running and returns at once (B.6); never part of one: a VERS
    sent before it is answered exactly once, whole, in that tick or the next."""
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        await probe.run(1)
        await probe.send("VERS", version=1)
        nested = await probe.run(1, gap=REENTRY_GAP_S)
        late = await probe.run(1)
        gap = REENTRY_GAP_S * 1e6
        once = f"one VERSION from the tick {gap:g} us after the previous one or from the next tick"
        expect_names(
            ctx, nested + late, ["VERSION"], clause="cougar.guts-reentry", expected=f"{once}, nothing else"
        )
        ctx.expect(
            not any(r.problem for r in nested + late),
            clause="cougar.guts-reentry",
            expected="every response of those ticks whole",
            seen=nested + late,
        )


@case(
    "cougar.guts.reentry",
    clauses=["cougar.guts-cost-model"],
)
async def guts_reentry(ctx: CaseContext) -> None:
    """A tick 0.5 ms after the previous one that finds GUTS still running (erratum cougar-guts-reentry's
    cost model) returns at once, and the command sent before it runs at the next tick instead.

    It checks clause cougar.guts-cost-model (SHOULD), not the MUST of cougar.guts-reentry (that is
    cougar.guts.no-nesting's).  A Cougar that runs a whole GUTS for that tick (one GUTS per TICK,
    docs/drv11j.md; or a GUTS faster than 0.5 ms: the VERS answered then, and not again) has no dropped
    tick to judge: the case is skipped."""
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        await probe.run(1)
        await probe.send("VERS", version=1)
        early = await probe.run(1, gap=0.0005)
        late = await probe.run(1)
        if [r.name for r in early] == ["VERSION"] and not late:
            ctx.skip(
                "this Cougar ran a whole GUTS for a tick 0.5 ms after the previous one: no re-entry to judge"
            )
        reentered = "no words from a tick that re-entered GUTS (or a whole GUTS: the VERS answered, once)"
        ctx.expect_none(early, clause="cougar.guts-cost-model", expected=reentered)
        expect_names(
            ctx,
            late,
            ["VERSION"],
            clause="cougar.guts-cost-model",
            expected="the VERS waiting in the buffer answered at the next full tick",
        )
