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
    f_float,
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
from manip.conformance.suite.context import CaseContext, Probe
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


def _angles_of(h: Heard, name: str) -> tuple[float, ...]:
    msg = h.msg
    assert msg is not None
    values = msg.values[name]
    assert isinstance(values, tuple)
    return tuple(float(v) for v in values)


def _joint6(h: Heard, name: str) -> float:
    return _angles_of(h, name)[5]


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


NOMINAL_WAY: Final = (0.0, 0.0, 0.0, 8.0, 0.0, 12.0)
"""Degrees each joint goes in ``puma.compliance.nominal-path``: joint 4, which Cougar never corrects,
gives the nominal path's fraction; joint 6 is the one corrected."""
REFERENCE_JOINT: Final = 3
"""Joint 4 (0-based): moving, and never corrected."""
PATH_TOL: Final = 0.01
"""Degrees a joint may stand off the line the nominal fraction gives (F floats of angles near 180
degrees carry about 1e-5)."""
STEP_TOL: Final = 1e-3
"""Degrees a cycle's correction may differ from NTD x T (or from none, before the first NTD)."""


def _fraction(sensed: Sequence[float], start: Sequence[float], goal: Sequence[float]) -> float:
    j = REFERENCE_JOINT
    return (sensed[j] - start[j]) / (goal[j] - start[j])


def _off_path(sensed: Sequence[float], start: Sequence[float], goal: Sequence[float]) -> list[float]:
    """How far each joint stands off the linear path at the fraction the reference joint gives."""
    f = _fraction(sensed, start, goal)
    return [s - (a + f * (b - a)) for s, a, b in zip(sensed, start, goal, strict=True)]


def _steps_wrong(offsets: Sequence[float], rate: float, first_by: int) -> str:
    """What is wrong with a corrected joint's offsets, one per cycle ('' if nothing): from one cycle to
    the next it moves by none before the first NTD arrives and by ``rate`` x T on every cycle from then,
    which is at the latest the ``first_by``-th."""
    steps = [b - a for a, b in itertools.pairwise(offsets)]
    first = next((i for i, d in enumerate(steps) if abs(d) > STEP_TOL), len(steps))
    want = rate * TICK
    wrong = [i for i in range(first, len(steps)) if abs(steps[i] - want) > STEP_TOL]  # none before first
    if wrong:
        i = wrong[0]
        return f"cycle {i + 1} moved it {steps[i]:+.4f} deg (want {want:+.4f})"
    if first > first_by:
        return f"no correction before cycle {first + 1} (want one by cycle {first_by + 1})"
    return ""


def _expect_adjusted_path(
    ctx: CaseContext,
    sensed: Sequence[Sequence[float]],
    start: Sequence[float],
    goal: Sequence[float],
    ntd: Sequence[float],
) -> None:
    """The sensed angles of each cycle: on the linear path from ``start`` to ``goal`` (at the reference
    joint's fraction), but for the joints ``ntd`` corrects, which leave it by NTD x T a cycle."""
    offsets = [_off_path(s, start, goal) for s in sensed]
    fractions = [_fraction(s, start, goal) for s in sensed]
    astray = [
        (k, j)
        for k, row in enumerate(offsets)
        for j, off in enumerate(row)
        if ntd[j] == 0.0 and abs(off) > PATH_TOL
    ]
    outside = [f for f in fractions if not -PATH_TOL <= f <= 1.0 + PATH_TOL]
    k, j = astray[0] if astray else (0, 0)
    seen = (
        f"cycle {k + 1}: joint {j + 1} {offsets[k][j]:+.4f} deg off, sensed {fmt(sensed[k])}"
        if astray
        else f"fractions {outside[:3]}"
    )
    ctx.expect(
        bool(sensed) and not astray and not outside,
        clause="puma.compliance.nominal-path",
        expected=f"every cycle's sensed angles on the line {fmt(start)} -> {fmt(goal)} (within {PATH_TOL:g} "
        f"deg, at joint {REFERENCE_JOINT + 1}'s fraction, between 0 and 1) but for the joints NTD corrects",
        seen=seen if sensed else missing("no New Position and Rate"),
    )
    # NTD's first reply comes on the tick after the first NPR: the second cycle may use it, and the sensed
    # angles of a cycle are the command of the one before.
    first_by = 1 + LATENCY_TICKS if is_virtual() else max(1 + LATENCY_TICKS, len(sensed) // 2)
    for j, rate in enumerate(ntd):
        if rate == 0.0:
            continue
        wrong = _steps_wrong([row[j] for row in offsets], rate, first_by)
        ctx.expect(
            len(sensed) > first_by + 1 and not wrong,
            clause="puma.compliance.nominal-path",
            expected=f"joint {j + 1} leaving the nominal path by {rate:g} deg/s x {TICK} s on every cycle "
            f"from the first NTD (by cycle {first_by + 1})",
            seen=f"{len(sensed)} cycles; {wrong}",
        )


async def _compliant_leg(
    ctx: CaseContext, probe: Probe, ntd: tuple[float, ...], start: Sequence[float], goal: Sequence[float]
) -> None:
    """A compliant move from ``start`` to ``goal`` with Cougar sending ``ntd``: its sensed angles on the
    path :func:`_expect_adjusted_path` wants."""
    judge, mark = begin(ctx, CougarScript(ntd=ntd))
    segment = await move(ctx, probe, "compliant-move", joints=list(goal), scheme=0)
    if await wait_async(ctx, probe, is_completed(segment), SEGMENT_WITHIN) is None:
        ctx.not_judged(
            f"the compliant segment {segment} was not reported complete within {SEGMENT_WITHIN:g} s "
            "(puma.compliance.segment-end judges that)"
        )
    sensed = [_angles_of(h, "theta_sensed") for h in _npr(judge, mark)]
    _expect_adjusted_path(ctx, sensed, start, goal, ntd)


@case(
    "puma.compliance.nominal-path",
    clauses=["puma.compliance.nominal-path"],
    hazard="motion",
    deadline=50.0,
)
async def nominal_path(ctx: CaseContext) -> None:
    """A compliant move with Cougar sending a zero New Theta Dot follows the linear scheme's path (the
    joints at one fraction of their ways) to its goal; the move back, with Cougar asking joint 6 for
    NTD_RATE deg/s, leaves joint 6 off that path by NTD_RATE x T more each cycle and joint 4 on it
    (erratum compliant-nominal-path)."""
    probe = await session(ctx)
    here = await angles(ctx, probe)
    away = tuple(f_float(h + d) for h, d in zip(here, NOMINAL_WAY, strict=True))
    await _compliant_leg(ctx, probe, (0.0,) * 6, here, away)
    rest = await angles(ctx, probe)
    if ctx.expect(
        close(rest, away, PATH_TOL),
        clause="puma.compliance.nominal-path",
        expected=f"with no correction the compliant segment ending at its goal {fmt(away)}",
        seen=f"joint angles {fmt(rest)}",
    ):  # the way back starts where the arm stands, within PATH_TOL of its goal
        await _compliant_leg(ctx, probe, (0.0,) * 5 + (NTD_RATE,), rest, here)
    back = await move(ctx, probe, "set-joint-angles", joints=list(here))
    await wait_async(ctx, probe, is_completed(back), SEGMENT_WITHIN)


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
