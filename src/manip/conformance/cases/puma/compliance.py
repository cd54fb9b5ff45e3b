"""Compliant motion (Part II §5.2, §6.4): New Position and Rate every cycle, the collision test off, and
the end of a compliant episode.  The judge answers each NPR with a chosen New Theta Dot (erratum
``compliant-schemes``: a joint-rate correction in deg/s that scheme 0 integrates into the path)."""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Final

from manip.conformance.cases._support import require_response
from manip.conformance.cases.puma._support import (
    SEGMENT_WITHIN,
    TICK,
    angles,
    begin,
    close,
    fmt,
    is_async_error,
    is_completed,
    move,
    session,
    wait_async,
)
from manip.conformance.judge.violation import missing
from manip.conformance.puma.judge import CougarScript, Heard, JudgingCougar, Said
from manip.conformance.puma.target import OBSTACLE_FROM, OBSTACLE_JOINT
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext
from manip.conformance.suite.world import Obstacle
from manip.links.virtual_clock import is_virtual
from manip.spec.constants import CougarCommand

NTD_RATE: Final = 4.0
"""Deg/s of correction the judge asks for on joint 6."""
MOVE_DEG: Final = 10.0
LATENCY_TICKS: Final = 4
"""Ticks an NTD may take to reach the Puma's interpolation (the reply comes on the tick after its NPR
at best; a TCP link adds its delay)."""
ARRIVED_DEG: Final = 1e-3


def _npr(judge: JudgingCougar, mark: int) -> list[Heard]:
    return judge.commands(mark, CougarCommand.NPR)


def _joint6(h: Heard, name: str) -> float:
    msg = h.msg
    assert msg is not None
    values = msg.values[name]
    assert isinstance(values, tuple)
    return float(values[5])


def _ntd_before(said: Sequence[Said], tick: int) -> int:
    """NTD responses among ``said`` sent on ticks before ``tick``."""
    return sum(1 for s in said if s.msg.name == "NTD" and s.tick < tick)


def _off_cycle(ticks: Sequence[int], late_allowed: bool) -> str:
    """What is wrong with the ticks NPRs arrived on ('' if nothing): one per cycle from the first.

    In virtual time neither the Puma's servo nor the judge ever falls behind, so each cycle's NPR
    arrives on its own tick.  In real time either may wake late and catch up several cycles at once, so
    NPRs arrive in bunches and only their count is held: one per cycle elapsed, give or take one at the
    ends."""
    if not ticks:
        return "none"
    span = ticks[-1] - ticks[0] + 1
    if late_allowed:
        return f"{len(ticks)} NPR for {span} cycles" if abs(len(ticks) - span) > 1 else ""
    missing = sorted(set(range(ticks[0], ticks[-1] + 1)) - set(ticks))
    doubled = sorted({t for t in ticks if ticks.count(t) > 1})
    return (f"none on ticks {missing[:8]}; " if missing else "") + (
        f"two or more on ticks {doubled[:8]}" if doubled else ""
    )


@case(
    "puma.compliance.npr-every-cycle",
    clauses=["puma.compliance.npr-every-cycle"],
    hazard="motion",
    deadline=40.0,
)
async def npr_every_cycle(ctx: CaseContext) -> None:
    """Every servo cycle of a compliant segment sends New Position and Rate, and the path uses the
    New Theta Dot received on earlier cycles."""
    probe = await session(ctx)
    here = await angles(ctx, probe)
    judge, mark = begin(ctx, CougarScript(ntd=(0.0, 0.0, 0.0, 0.0, 0.0, NTD_RATE)))
    said_before = len(judge.said)
    goal = [*here[:5], here[5] + MOVE_DEG]
    segment = await move(ctx, probe, "compliant-move", joints=goal, scheme=0)
    done = await wait_async(ctx, probe, is_completed(segment), SEGMENT_WITHIN)
    if done is None:
        ctx.not_judged(
            f"the compliant segment {segment} was not reported complete within {SEGMENT_WITHIN:g} s "
            "(puma.compliance.segment-end judges that)"
        )
    npr = _npr(judge, mark)
    ticks = [h.tick for h in npr]
    wrong = _off_cycle(ticks, late_allowed=not is_virtual())
    ctx.expect(
        len(npr) >= 3 and not wrong,
        clause="puma.compliance.npr-every-cycle",
        expected="one New Position and Rate for every servo cycle of the compliant segment",
        seen=f"{len(npr)} NPR on ticks {ticks[:1]}..{ticks[-1:]}: {wrong}",
    )
    # The correction of cycle k (commanded_k - nominal_k) shows in the next NPR's sensed angles:
    # sensed_{k+1} - nominal_k.  It may use only NTDs sent before cycle k's NPR, and all but the last few.
    said = judge.said[said_before:]
    for before, after in itertools.pairwise(npr):
        offset = _joint6(after, "theta_sensed") - _joint6(before, "theta_commanded")
        sent = _ntd_before(said, before.tick)
        most = NTD_RATE * TICK * sent + ARRIVED_DEG
        least = NTD_RATE * TICK * (sent - LATENCY_TICKS) - ARRIVED_DEG
        ctx.expect(
            least <= offset <= most,
            clause="puma.compliance.npr-every-cycle",
            expected=f"joint 6 held {NTD_RATE:g} deg/s x {TICK} s per NTD received before the cycle: "
            f"between {least:.4f} and {most:.4f} deg off the nominal path on tick {before.tick}",
            seen=f"{offset:.4f} deg ({sent} NTD sent before that tick; {len(said)} in all)",
        )
    ctx.note(f"{len(npr)} NPR on ticks {ticks[0]}..{ticks[-1]}")


@case(
    "puma.compliance.segment-end",
    clauses=["puma.compliance.segment-end"],
    hazard="motion",
    deadline=50.0,
)
async def segment_end(ctx: CaseContext) -> None:
    """A compliant segment ends where compliance left the arm (no jump back to the nominal goal), and
    the next segment starts from there and reaches its goal."""
    probe = await session(ctx)
    here = await angles(ctx, probe)
    judge, mark = begin(ctx, CougarScript(ntd=(0.0, 0.0, 0.0, 0.0, 0.0, NTD_RATE)))
    goal = [*here[:5], here[5] + MOVE_DEG]
    segment = await move(ctx, probe, "compliant-move", joints=goal, scheme=0)
    done = await wait_async(ctx, probe, is_completed(segment), SEGMENT_WITHIN)
    ctx.expect(
        done is not None,
        clause="puma.compliance.segment-end",
        expected=f"the compliant segment {segment} reported complete within {SEGMENT_WITHIN:g} s (its "
        "clean-up done, as for any segment)",
        seen=missing("no segment-completed report"),
    )
    judge.begin(CougarScript(ntd=(0.0,) * 6))
    await judge.wait_ticks(3, SEGMENT_WITHIN)
    rest = await angles(ctx, probe)
    npr = _npr(judge, mark)
    if len(npr) < 2:
        ctx.not_judged(
            "the Puma sent fewer than two New Position and Rate commands (npr-every-cycle judges that)"
        )
    last = npr[-1]
    held = _joint6(last, "theta_sensed") - _joint6(npr[-2], "theta_commanded")
    ctx.expect(
        abs(held) > ARRIVED_DEG and close(rest[5:], [goal[5] + held], max(0.25 * abs(held), 0.01)),
        clause="puma.compliance.segment-end",
        expected=f"the arm at rest where compliance left it: joint 6 near {goal[5] + held:.4f} "
        f"(goal {goal[5]:g} plus the {held:.4f} deg correction held on the last cycle)",
        seen=f"joint angles {fmt(rest)}",
    )
    back = await move(ctx, probe, "set-joint-angles", joints=list(here))
    finished = await wait_async(ctx, probe, is_completed(back), SEGMENT_WITHIN)
    final = await angles(ctx, probe)
    ctx.expect(
        finished is not None and close(final, here, ARRIVED_DEG),
        clause="puma.compliance.segment-end",
        expected=f"the next segment ({back}) started from there, completed and reached {fmt(here)}",
        seen=f"{'completed' if finished else 'not reported complete'}; joint angles {fmt(final)}",
    )


@case(
    "puma.compliance.no-collision-test",
    clauses=["puma.compliance.no-collision-test"],
    hazard="motion",
    deadline=60.0,
)
async def no_collision_test(ctx: CaseContext) -> None:
    """A compliant move pushing into an obstacle is not stopped by the collision test (a plain move
    into it is: the case's precondition).  The target's world puts the obstacle in joint 1's way (the
    embedded Puma's world always, another Puma's with ``--world``); without a world the case is not
    judged."""
    async with ctx.arranged(Obstacle(OBSTACLE_JOINT, upper=OBSTACLE_FROM)):
        await _no_collision_test(ctx)


async def _no_collision_test(ctx: CaseContext) -> None:
    probe = await session(ctx)
    here = await angles(ctx, probe)
    j = OBSTACLE_JOINT - 1
    if here[j] >= OBSTACLE_FROM:
        ctx.skip(f"joint {OBSTACLE_JOINT} stands at {here[j]:g}, past where the obstacle would be")
    judge, _ = begin(ctx, CougarScript(ntd=(0.0,) * 6))  # compliance changes nothing: only the test differs
    into = list(here)
    into[j] = OBSTACLE_FROM + 10.0
    plain = await move(ctx, probe, "set-joint-angles", joints=into)
    hit = await wait_async(ctx, probe, lambda p: is_async_error(p) or is_completed(plain)(p), SEGMENT_WITHIN)
    if hit is None or not is_async_error(hit):
        ctx.not_judged(
            f"a plain move of joint {OBSTACLE_JOINT} past {OBSTACLE_FROM:g} deg did not collide although the "
            "world arranged an obstacle there: no collision test to judge"
        )
    require_response(ctx, await probe.call("reset-abort"), "reset abort after the collision")
    start = await move(ctx, probe, "set-joint-angles", joints=list(here))
    await wait_async(ctx, probe, is_completed(start), SEGMENT_WITHIN)
    seen = len(probe.unsolicited)
    push = await move(ctx, probe, "compliant-move", joints=into, scheme=0)
    back = await move(ctx, probe, "compliant-move", joints=list(here), scheme=0)
    returned = is_completed(back)
    end = await wait_async(
        ctx, probe, lambda p: is_async_error(p) or returned(p), 2 * SEGMENT_WITHIN, after=seen
    )
    errors = [p for p in probe.unsolicited[seen:] if is_async_error(p)]
    ctx.expect(
        end is not None and not errors,
        clause="puma.compliance.no-collision-test",
        expected=f"compliant segments {push} (into the obstacle) and {back} (back) completed with no "
        "collision error",
        seen=(errors or end) or missing("neither completion nor error"),
    )
    ctx.note(f"judge heard {judge.ticks} ticks")
