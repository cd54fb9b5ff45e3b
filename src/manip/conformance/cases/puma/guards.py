"""Guards (Part III B.9, E.3 opcode 203, erratum ``guard-stop``): the judge trips a guard the Puma set,
while the arm moves, and the case watches the arm and the asynchronous responses."""

from __future__ import annotations

from collections.abc import Callable
from typing import Final

from manip.conformance.cases._support import require_response
from manip.conformance.cases.puma._support import (
    CONTINUE_WORD,
    SEGMENT_WITHIN,
    STOP_WORD,
    angles,
    async_words,
    begin,
    close,
    fmt,
    is_completed,
    is_guard_hit,
    move,
    session,
    wait_async,
)
from manip.conformance.judge.checks import WirePacket
from manip.conformance.puma.judge import JudgingCougar
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext, Probe
from manip.spec.constants import AsyncCondition

STOP_BIT: Final = 0x8000
NEVER: Final = 1.0e30
"""A tolerance no force reaches: the guard trips only when the judge says so."""
MOVE_DEG: Final = 60.0
"""A move long enough to trip a guard in the middle of it."""
MOVING_DEG: Final = 2.0
STILL_TICKS: Final = 10
REPORT_WITHIN: Final = 1.0
"""Seconds from a trip to its asynchronous response (the Puma reports what its processes queued each
time through its main loop, Part II §5.1)."""
ARRIVED_DEG: Final = 1e-3


async def _arm_guard(ctx: CaseContext, probe: Probe, index: int, *, stop: bool) -> None:
    word = (STOP_BIT if stop else 0) | index
    answer = await probe.call("set-guard", type_index=word, dvec=[0.0] * 6, tol=NEVER)
    require_response(ctx, answer, "set-guard answered done")


async def _moving(ctx: CaseContext, judge: JudgingCougar, start: float) -> None:
    """Until the sensed angles the Puma sends show joint 6 on its way."""

    def on_the_way() -> bool:
        return judge.pose is not None and abs(judge.pose[5] - start) > MOVING_DEG

    if not await judge.wait_for(on_the_way, SEGMENT_WITHIN):
        ctx.skip("the Puma sent Cougar no sensed angles showing the arm move (erratum wrist-sen)")


def _guard_hit(word2: int, index: int) -> Callable[[WirePacket], bool]:
    def match(p: WirePacket) -> bool:
        return is_guard_hit(p) and async_words(p)[1:3] == (word2, index)

    return match


@case("puma.guard.stop", clauses=["puma.guard.stop"], hazard="motion", deadline=60.0)
async def guard_stop(ctx: CaseContext) -> None:
    """A stop-the-move guard trip stops the arm and drops the current and queued segments; a
    continue guard trip leaves the motion alone."""
    probe = await session(ctx)
    here = await angles(ctx, probe)
    judge, _ = begin(ctx)
    g = ctx.random.randrange(16)
    await _arm_guard(ctx, probe, g, stop=True)
    far = [*here[:5], here[5] + MOVE_DEG]
    first = await move(ctx, probe, "set-joint-angles", joints=far)
    second = await move(ctx, probe, "set-joint-angles", joints=list(here))
    await _moving(ctx, judge, here[5])
    judge.inject("GUARD-STOP", index=g)
    await judge.wait_ticks(3, SEGMENT_WITHIN)
    a = await angles(ctx, probe)
    await judge.wait_ticks(STILL_TICKS, SEGMENT_WITHIN)
    b = await angles(ctx, probe)
    ctx.expect(
        close(a, b, ARRIVED_DEG) and not close(a, far, MOVING_DEG),
        clause="puma.guard.stop",
        expected=f"the arm stopped short of {fmt(far)} after stop guard {g} tripped",
        seen=f"joint angles {fmt(a)}, then {STILL_TICKS} ticks later {fmt(b)}",
    )
    late = await wait_async(ctx, probe, lambda p: is_completed(first)(p) or is_completed(second)(p), 1.0)
    ctx.expect(
        late is None,
        clause="puma.guard.stop",
        expected=f"segments {first} and {second} dropped: never reported complete",
        seen=late,
    )
    # A continue guard: the motion goes on to its goal.
    require_response(ctx, await probe.call("reset-abort"), "reset abort after the guard stop")
    h = (g + 1 + ctx.random.randrange(15)) % 16
    await _arm_guard(ctx, probe, h, stop=False)
    start = await angles(ctx, probe)
    third = await move(ctx, probe, "set-joint-angles", joints=list(here))
    await _moving(ctx, judge, start[5])
    judge.inject("GUARD-CONTINUE", index=h)
    done = await wait_async(ctx, probe, is_completed(third), SEGMENT_WITHIN)
    final = await angles(ctx, probe)
    ctx.expect(
        done is not None and close(final, here, ARRIVED_DEG),
        clause="puma.guard.stop",
        expected=f"segment {third} completed at {fmt(here)} although continue guard {h} tripped",
        seen=f"{'completed' if done else 'not reported complete'}; joint angles {fmt(final)}",
    )


@case("puma.guard.report", clauses=["puma.guard.report"], hazard="motion", deadline=60.0)
async def guard_report(ctx: CaseContext) -> None:
    """Guard trips are reported as asynchronous responses (1, 1 stopped / 2 continues, guard number)."""
    probe = await session(ctx)
    here = await angles(ctx, probe)
    judge, _ = begin(ctx)
    g = ctx.random.randrange(16)
    h = (g + 1 + ctx.random.randrange(15)) % 16
    await _arm_guard(ctx, probe, h, stop=False)
    await _arm_guard(ctx, probe, g, stop=True)
    far = [*here[:5], here[5] + MOVE_DEG]
    await move(ctx, probe, "set-joint-angles", joints=far)
    await _moving(ctx, judge, here[5])
    judge.inject("GUARD-CONTINUE", index=h)
    cont = await wait_async(ctx, probe, _guard_hit(CONTINUE_WORD, h), REPORT_WITHIN)
    ctx.expect(
        cont is not None,
        clause="puma.guard.report",
        expected=f"asynchronous response (203) {AsyncCondition.GUARD_HIT:d}, {CONTINUE_WORD}, {h} within "
        f"{REPORT_WITHIN:g} s of continue guard {h} tripping",
        seen=probe.unsolicited or "nothing",
    )
    judge.inject("GUARD-STOP", index=g)
    stop = await wait_async(ctx, probe, _guard_hit(STOP_WORD, g), REPORT_WITHIN)
    ctx.expect(
        stop is not None,
        clause="puma.guard.report",
        expected=f"asynchronous response (203) {AsyncCondition.GUARD_HIT:d}, {STOP_WORD}, {g} within "
        f"{REPORT_WITHIN:g} s of stop guard {g} tripping",
        seen=probe.unsolicited or "nothing",
    )
    # Put the arm back for the cases after this one.
    await probe.call("reset-abort")
    back = await move(ctx, probe, "set-joint-angles", joints=list(here))
    await wait_async(ctx, probe, is_completed(back), SEGMENT_WITHIN)
