"""Motion and arm state (E.1, E.2, Part II §6.2): JOR, TOR, NAP, AWA and its reset, speed factor,
segment numbers and asynchronous segment-completed responses, free joint."""

from __future__ import annotations

import asyncio
import math
from itertools import pairwise
from typing import Final

from manip.codecs.messages import ErrorReply
from manip.conformance.cases._support import (
    SEGMENT_MASK,
    TargetArm,
    ask_notifications,
    describe_target,
    expect_error_numbers,
    expect_here_served,
    expect_refusal,
    extension_name,
    floats,
    host_delay,
    length,
    not_judged_for_load,
    out_of_range_mask,
    power_on,
    read_floats,
    require_response,
    settle,
    timed_move,
)
from manip.conformance.judge.checks import async_of, check_async_packet, word
from manip.conformance.judge.violation import missing, showing
from manip.conformance.suite.case import case
from manip.conformance.suite.context import Answer, CaseContext, Probe
from manip.spec import SPEC, RequestName
from manip.spec.constants import AsyncCondition, ServerOp

FAR_MM = 100_000.0
"""A position 100 m away: no manipulator reaches it."""
OUT_OF_RANGE_DEG = 1000.0
"""A joint angle past any revolute joint's limit."""
SMALL_STEP_DEG = 2.0
SEGMENT_REPLY_SIZE = 4
"""Data bytes of a segment-number reply: request number and segment number."""
CONFIGURATION_SEED: Final = (20.0, -60.0, 150.0, 0.0, -60.0, 0.0)
"""Joint angles whose transform a PUMA reaches within its limits lefty and righty (and is not singular)."""
SLOW_FACTOR: Final = 0.25
"""The speed factor the fresh-state case leaves behind on the connection it closes."""
SPEED_MATCH: Final = 1.5
"""How much longer than at factor 1 a fresh connection's move may take (at 0.25 it takes 4 times)."""


async def _wait_still(ctx: CaseContext, probe: Probe, limit: float = 5.0) -> None:
    """Poll joint angles until two readings 0.1 s apart agree (the queued motion has ended)."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + limit
    last = await read_floats(ctx, probe, "joint-angles")
    while loop.time() < deadline:
        await asyncio.sleep(0.1)
        now = await read_floats(ctx, probe, "joint-angles")
        if max(abs(a - b) for a, b in zip(now, last, strict=True)) < 1e-4:
            return
        last = now


def _shifted(joints: tuple[float, ...], joint: int, by: float) -> list[float]:
    out = list(joints)
    out[joint] += by
    return out


def _away_from_zero(joints: tuple[float, ...], by: float) -> list[float]:
    """``joints`` with joint 1 moved ``by`` degrees, towards zero (so the move stays in range)."""
    direction = -1.0 if joints[0] > 0 else 1.0
    return _shifted(joints, 0, direction * by)


def _expect_segment_reply(ctx: CaseContext, answer: Answer, expected: str) -> None:
    ctx.expect_response(answer, clause="response.segment-number", expected=expected, size=SEGMENT_REPLY_SIZE)


async def _small_move(
    ctx: CaseContext, probe: Probe, by: float = SMALL_STEP_DEG, *, clause: str | None = None
) -> int:
    """A small joint move of joint 1; returns its segment number.  With ``clause`` the move being
    accepted is what the case checks; without, the case needs the move and is not judged when it is
    refused."""
    joints = await read_floats(ctx, probe, "joint-angles")
    answer = await probe.call("set-joint-angles", joints=_away_from_zero(joints, by))
    if clause is None:
        require_response(ctx, answer, "a small move of joint 1 accepted")
    else:
        ctx.expect_response(
            answer,
            clause=clause,
            expected="a segment-number reply to set joint angles",
            size=SEGMENT_REPLY_SIZE,
        )
    segment = word(answer.data, 2)
    assert segment is not None
    return segment


async def _refused_stay(
    ctx: CaseContext,
    probe: Probe,
    joints: tuple[float, ...],
    *,
    clause: str,
    codes: tuple[str, ...],
    what: str,
) -> None:
    """Ask the arm to move to ``joints`` (where it stands): the answer must be an E error of ``codes``."""
    answer = await probe.call("set-joint-angles", joints=list(joints))
    expect_refusal(ctx, answer, clause=clause, severities=("E",), codes=codes, what=what)


@case(
    "server.motion.jor", clauses=["motion.checked-before-queue", "error-string.arg-values"], hazard="motion"
)
async def joint_out_of_range(ctx: CaseContext) -> None:
    """Set joint angles with joints 1 and 4 past their limits: JOR at once, its $ mask naming those
    joints (computed here from the request and the limits), and the arm does not move."""
    probe = await ctx.connect()
    arm = await describe_target(ctx, probe)
    await power_on(ctx, probe)
    before = await read_floats(ctx, probe, "joint-angles")
    goal = _shifted(tuple(_shifted(before, 0, OUT_OF_RANGE_DEG)), 3, OUT_OF_RANGE_DEG)
    answer = await probe.call("set-joint-angles", joints=goal)
    error = expect_refusal(
        ctx,
        answer,
        clause="motion.checked-before-queue",
        severities=("E", "C"),
        codes=("JOR",),
        what=f"joints 1 and 4 at {goal[0]:g} and {goal[3]:g} degrees",
    )
    mask = out_of_range_mask(goal, arm.limits)
    expect_error_numbers(
        ctx, answer, error, [(mask,)], what=f"JOR of joints at {[round(q, 1) for q in goal]}"
    )
    await asyncio.sleep(0.1)
    after = await read_floats(ctx, probe, "joint-angles")
    moved = max(abs(a - b) for a, b in zip(before, after, strict=True))
    ctx.expect(
        moved < 0.01,
        clause="motion.checked-before-queue",
        expected="the arm standing still",
        seen=f"a joint moved by {moved:.3f} degrees",
    )


@case("server.motion.tor", clauses=["solve-forwards.errors", "motion.checked-before-queue"], hazard="motion")
async def transform_out_of_reach(ctx: CaseContext) -> None:
    """A transform 100 m away: solve forwards and move answer a non-fatal error (any code: erratum
    unnamed-error-codes; manip's server says TOR)."""
    probe = await ctx.connect()
    pose = list(await read_floats(ctx, probe, "here"))
    joints = list(await read_floats(ctx, probe, "joint-angles"))
    far = [*pose[:9], length(ctx, FAR_MM), 0.0, 0.0]
    answer = await probe.call("solve-forwards", transform=far, current=joints)
    expect_refusal(  # any code: the 1985 guide names none for a place out of reach (manip's is TOR)
        ctx,
        answer,
        clause="solve-forwards.errors",
        severities=("E", "C"),
        what="solve forwards to a point 100 m away",
    )
    await power_on(ctx, probe)
    answer = await probe.call("move", transform=far)
    expect_refusal(
        ctx,
        answer,
        clause="motion.checked-before-queue",
        severities=("E", "C"),
        what="a move to a point 100 m away",
    )


LIMIT_OVERSHOOT_DEG = 10.0
"""How far past a stated limit the tor-limits case puts a joint to make its transform."""
LIMIT_JOINTS = (2, 3, 5)
"""Joints whose range, not a second solution, decides reachability on a PUMA: past either limit of any
of them, every solution of the transform breaks a limit (the other joints have a second solution)."""


def _limit_candidates(arm: TargetArm, joints: tuple[float, ...]) -> list[tuple[int, list[float]]]:
    """Joint vectors with one joint :data:`LIMIT_OVERSHOOT_DEG` past one of its stated limits."""
    out: list[tuple[int, list[float]]] = []
    for j in (j for j in LIMIT_JOINTS if j <= len(joints)):
        lo, hi = arm.limits.lower[j - 1], arm.limits.upper[j - 1]
        for bound in (hi + LIMIT_OVERSHOOT_DEG, lo - LIMIT_OVERSHOOT_DEG):
            q = list(joints)
            q[j - 1] = bound
            out.append((j, q))
    return out


def _expect_tor_mask(
    ctx: CaseContext, answer: Answer, error: ErrorReply | None, joint: int, dof: int
) -> None:
    """TOR's every-solution form names the joints out of range: the one put past its limit among them,
    none beyond the arm's (erratum error-arg-values; other joints may break a limit in that solution)."""
    if error is None or len(error.error.args) != 1:
        return
    mask = error.error.args[0]
    ctx.expect(
        bool(mask >> (joint - 1) & 1) and mask >> dof == 0,
        clause="error-string.arg-values",
        expected=f"a joint mask holding joint {joint} and no joint beyond {dof}",
        seen=showing(answer, f"mask {mask:#06x} in {error.error.render()!r}"),
    )


@case(
    "server.motion.tor-limits",
    clauses=["solve-forwards.errors", "motion.checked-before-queue", "error-string.arg-values"],
    hazard="motion",
    deadline=10.0,
)
async def transform_out_of_range(ctx: CaseContext) -> None:
    """A transform whose every solution breaks a joint limit: solve forwards and move answer TOR, not JOR
    (the 1985 guide's TOR; erratum transform-refusals).  The transform is the target's own solve
    backwards of angles with one joint past a limit; one the target solves in range is passed over."""
    probe = await ctx.connect()
    arm = await describe_target(ctx, probe)
    here = await read_floats(ctx, probe, "joint-angles")
    for joint, q in _limit_candidates(arm, here):
        back = await probe.call("solve-backwards", joints=q)
        if not back.is_response:
            continue
        transform = list(floats(back))
        answer = await probe.call("solve-forwards", transform=transform, current=list(here))
        if answer.is_response:
            continue  # another configuration reaches it within the limits: no verdict from this one
        what = f"the transform of joint {joint} at {q[joint - 1]:g} degrees (every solution out of range)"
        error = expect_refusal(
            ctx, answer, clause="solve-forwards.errors", severities=("E", "C"), codes=("TOR",), what=what
        )
        _expect_tor_mask(ctx, answer, error, joint, arm.dof)
        await power_on(ctx, probe)
        answer = await probe.call("move", transform=transform)
        expect_refusal(
            ctx,
            answer,
            clause="motion.checked-before-queue",
            severities=("E", "C"),
            codes=("TOR",),
            what=f"a move to {what}",
        )
        return
    ctx.not_judged(
        "solve forwards found in-range angles for every transform tried (joints 2, 3, 5 past a limit), so no "
        "TOR was provoked"
    )


@case("server.motion.nap", clauses=["motion.no-power", "kill-power.done"], hazard="power")
async def no_arm_power(ctx: CaseContext) -> None:
    """After kill power, motion is refused with NAP; enable power makes it accepted again."""
    probe = await ctx.connect()
    answer = await probe.call("kill-power")
    ctx.expect_done(answer, clause="kill-power.done", expected="an empty done")
    joints = await read_floats(ctx, probe, "joint-angles")
    await _refused_stay(
        ctx, probe, joints, clause="motion.no-power", codes=("NAP",), what="a move without arm power"
    )
    await power_on(ctx, probe)
    await _small_move(ctx, probe, 0.5, clause="motion.no-power")  # power back: motion accepted again


async def _abort_by_power_loss(ctx: CaseContext, probe: Probe) -> None:
    """Start a long move, kill power while it runs: the move process must report an abort."""
    await power_on(ctx, probe)
    joints = await read_floats(ctx, probe, "joint-angles")
    answer = await probe.call("set-joint-angles", joints=_away_from_zero(joints, 30.0))
    require_response(ctx, answer, "a 30-degree move accepted")
    await asyncio.sleep(0.05)
    await probe.call("kill-power")
    loop = asyncio.get_running_loop()
    deadline = loop.time() + ctx.options.reply_timeout
    while not any(p.opcode == ServerOp.ASYNCHRONOUS_ERROR for p in probe.unsolicited):
        packet = await probe.next_packet(max(0.0, deadline - loop.time()))
        if packet is None:
            break
        probe.unsolicited.append(packet)
    aborts = [p for p in probe.unsolicited if p.opcode == ServerOp.ASYNCHRONOUS_ERROR]
    ctx.expect(
        aborts,
        clause="motion.abort",
        expected="an asynchronous error (0204) when power is lost during a move",
        seen=missing("no asynchronous error", after=answer),
    )


@case(
    "server.motion.awa-reset-by-power",
    clauses=["motion.abort", "motion.reset", "async-error.request-number"],
    hazard="power",
)
async def awa_reset_by_power(ctx: CaseContext) -> None:
    """Power lost during a move aborts it; motion is then refused (AWA, or NAP) until enable power."""
    probe = await ctx.connect()
    await _abort_by_power_loss(ctx, probe)
    last_request = max(p.packet_no for p in probe.packets if p.direction == "c2s")
    for packet in (p for p in probe.unsolicited if p.opcode == ServerOp.ASYNCHRONOUS_ERROR):
        ctx.expect(
            (word(packet.data) or 0) <= last_request and len(packet.data) >= 2,
            clause="async-error.request-number",
            expected="the number of the last request processed",
            seen=showing(packet, str(word(packet.data))),
        )
    joints = await read_floats(ctx, probe, "joint-angles")
    await _refused_stay(
        ctx, probe, joints, clause="motion.abort", codes=("AWA", "NAP"), what="a move after an abort"
    )
    await power_on(ctx, probe)
    await _small_move(ctx, probe, 0.5, clause="motion.reset")  # enable power reset the abort


@case(
    "server.motion.awa-reset-abort",
    clauses=["motion.abort", "motion.abort-serves-others", "motion.reset"],
    hazard="power",
    extensions=["reset-abort"],
)
async def awa_reset_abort(ctx: CaseContext) -> None:
    """After an abort, motion is refused with AWA while other requests should be served (erratum
    awa-scope: refusing them too, as E.2 reads, only warns); Reset abort (260) clears AWA without
    restoring power: then NAP, not AWA.  A target without Reset abort (a Puma extension) has the abort
    reset the 1985 guide's way, by enable high power (217)."""
    probe = await ctx.connect()
    joints = await read_floats(ctx, probe, "joint-angles")  # in range: a refusal can only be the abort's
    await _abort_by_power_loss(ctx, probe)
    await _refused_stay(
        ctx,
        probe,
        joints,
        clause="motion.abort",
        codes=("AWA",),
        what="a move after an abort (the abort is reported before the missing power)",
    )
    # only motion need be refused: the client should still be able to ask where the arm stands
    served: tuple[tuple[RequestName, dict[str, float], str], ...] = (
        ("here", {}, "the transform"),
        ("joint-angles", {}, "the joint angles"),
        ("set-speed", {"factor": 0.5}, "an empty done"),
    )
    for op, values, what in served:
        answer = await probe.call(op, **values)
        ctx.expect_response(
            answer,
            clause="motion.abort-serves-others",
            expected=f"{op} answered with {what} while motion is aborted",
        )
    reset = await probe.call("reset-abort")
    if not reset.is_response:
        ctx.note(
            f"the target refused {extension_name('reset-abort')} ({reset}): the abort is reset by enable "
            "high power (0217), as Part II §6.2 allows"
        )
        await power_on(ctx, probe)
        await _small_move(ctx, probe, 0.5, clause="motion.reset")
        return
    await _refused_stay(
        ctx,
        probe,
        joints,
        clause="motion.reset",
        codes=("NAP",),
        what="a move after Reset abort without power",
    )


@case(
    "server.motion.reply-before-motion",
    clauses=["motion.reply-before-motion", "response.segment-number"],
    hazard="motion",
)
async def reply_before_motion(ctx: CaseContext) -> None:
    """A 20-degree move is answered at once, while the arm is still on its way."""
    probe = await ctx.connect()
    await power_on(ctx, probe)
    before = await read_floats(ctx, probe, "joint-angles")
    goal = _away_from_zero(before, 20.0)
    start = ctx.clock()
    # Waited for as long as the segment may take: a reply held until the arm arrives is then seen late,
    # and judged so, rather than missed.
    wait = SPEC.segment_within * ctx.options.deadline_scale
    answer = await probe.call("set-joint-angles", joints=goal, timeout=max(ctx.options.reply_timeout, wait))
    took = ctx.clock() - start
    _expect_segment_reply(ctx, answer, "a segment-number reply")
    now = await read_floats(ctx, probe, "joint-angles")
    ctx.expect(
        abs(now[0] - goal[0]) > 0.5,
        clause="motion.reply-before-motion",
        expected="the reply before the arm reaches the goal",
        seen=f"joint 1 already at {now[0]:.2f} (goal {goal[0]:.2f}) when the reply came after {took:.3f} s",
    )
    ctx.note(f"move answered in {took * 1000:.1f} ms")


@case("server.motion.segment-numbers", clauses=["segment.number-increases"], hazard="motion")
async def segment_numbers(ctx: CaseContext) -> None:
    """Consecutive motion requests get segment numbers n, n+1, n+2."""
    probe = await ctx.connect()
    await power_on(ctx, probe)
    numbers = [await _small_move(ctx, probe, 0.5 * (-1) ** i) for i in range(3)]
    ok = all(b == (a + 1) & 0xFFFF for a, b in pairwise(numbers))
    ctx.expect(
        ok,
        clause="segment.number-increases",
        expected="segment numbers increasing by one",
        seen=f"segments {numbers}",
    )


@case("server.speed.bounds", clauses=["speed.range"], hazard="config")
async def speed_bounds(ctx: CaseContext) -> None:
    """Set speed factor: 0 < n <= 1 accepted; 0, negative and above 1 refused with C."""
    probe = await ctx.connect()
    for factor in (1.0, 0.5, 2.0**-20):
        answer = await probe.call("set-speed", factor=factor)
        ctx.expect_done(answer, clause="speed.range", expected=f"done for speed factor {factor!r}")
    for factor in (0.0, -0.5, 1.0 + 2.0**-20, 2.0, 1e30):
        answer = await probe.call("set-speed", factor=factor)
        expect_refusal(ctx, answer, clause="speed.range", what=f"speed factor {factor!r}")


async def _segment_time(ctx: CaseContext, probe: Probe, factor: float, by: float, *, notified: bool) -> float:
    answer = await probe.call("set-speed", factor=factor)
    require_response(ctx, answer, f"speed factor {factor!r} accepted")
    return await _timed_small_move(ctx, probe, by, notified=notified)


async def _timed_small_move(ctx: CaseContext, probe: Probe, by: float, *, notified: bool) -> float:
    """Seconds a move of joint 1 by ``by`` degrees (towards zero) takes, on the run's clock (simulated
    seconds in virtual time): by its segment-completed report, or by polling (:func:`timed_move`)."""
    joints = await read_floats(ctx, probe, "joint-angles")
    return await timed_move(ctx, probe, _away_from_zero(joints, by), notified=notified)


@case(
    "server.async.segment-completed",
    clauses=["async.layout", "async.codes", "async.only-when-requested"],
    hazard="motion",
    deadline=10.0,
    extensions=["request-notifications"],
)
async def segment_completed(ctx: CaseContext) -> None:
    """Asked for (request-notifications bit 1), a finished segment is reported by 0203 code 2; not
    asked for, nothing is reported."""
    probe = await ctx.connect()
    await power_on(ctx, probe)
    await _small_move(ctx, probe, 1.0)
    await _wait_still(ctx, probe)
    quiet = await probe.drain(0.3)
    unrequested = [p for p in quiet if p.opcode == ServerOp.ASYNCHRONOUS_RESPONSE]
    ctx.expect(
        not unrequested,
        clause="async.only-when-requested",
        expected="no asynchronous response before any was asked for",
        seen=showing(unrequested[:1], f"{len(unrequested)} asynchronous response(s)"),
    )
    if not await ask_notifications(ctx, probe):
        ctx.not_judged(
            "no asynchronous response came unasked (async.only-when-requested held), but the 1985 guide "
            "gives no request to ask for segment-completed responses; the layout of one (async.layout, "
            f"async.codes) is judged on a target that serves {extension_name('request-notifications')}"
        )
    segment = await _small_move(ctx, probe, 1.0)
    seen: list[int | None] = []
    while (packet := await probe.next_packet(3.0)) is not None:
        if packet.opcode != ServerOp.ASYNCHRONOUS_RESPONSE:
            continue
        ctx.check(check_async_packet(packet, 1 << 1))
        message = async_of(packet)
        ctx.expect(  # a packet of neither layout is async.layout's, which check_async_packet names
            message is None or message.condition == AsyncCondition.SEGMENT_COMPLETED,
            clause="async.codes",
            expected="condition code 2 (segment completed)",
            seen=showing(packet, f"condition {message.condition if message else None}"),
        )
        seen.append(message.word3 if message else None)
        if seen[-1] == segment:
            return
    ctx.fail(
        f"no segment-completed response for segment {segment}",
        clause="async.layout",
        expected=f"an asynchronous segment-completed response for segment {segment}",
        seen=f"segments reported: {seen}",
    )


@case(
    "server.speed.scales",
    clauses=["motion.speed-scales"],
    hazard="motion",
    deadline=12.0,
    extensions=["request-notifications"],
)
async def speed_scales(ctx: CaseContext) -> None:
    """A move at speed factor 0.25 takes longer than the same move at 1 (timed by its segment-completed
    report, or, on a target without request notifications, by polling the joint angles until it ends)."""
    probe = await ctx.connect()
    await power_on(ctx, probe)
    notified = await ask_notifications(ctx, probe, SEGMENT_MASK)
    delay = await host_delay(ctx)
    fast = await _segment_time(ctx, probe, 1.0, 1.0, notified=notified)
    slow = await _segment_time(ctx, probe, 0.25, -1.0, notified=notified)
    delay = max(delay, await host_delay(ctx))
    ctx.note(f"1-degree move: {fast:.3f} s at 1.0, {slow:.3f} s at 0.25")
    # The host's delays lengthen a timing by up to `delay`: a failure is one even with the fast move
    # that much shorter, a pass one even with the slow move that much shorter.
    if (
        ctx.expect(
            slow > (fast - delay) * 1.3,
            clause="motion.speed-scales",
            expected="the slow move taking longer",
            seen=f"{fast:.3f} s at speed 1, {slow:.3f} s at speed 0.25",
        )
        and slow - delay <= fast * 1.3
    ):
        not_judged_for_load(
            ctx,
            f"the moves took {fast:.3f} s at speed 1 and {slow:.3f} s at 0.25, and the case's own timers "
            f"ended up to {delay * 1000:.1f} ms late: too close to tell; an idle host would judge it",
        )


@case(
    "server.free-joint.discard",
    clauses=["free-joint.awaits-next-packet", "free-joint.replies", "free-joint.data"],
    hazard="motion",
)
async def free_joint_discard(ctx: CaseContext) -> None:
    """Free joint 1: done; the next packet (Here) gets an empty done, not its data; then Here works."""
    probe = await ctx.connect()
    await power_on(ctx, probe)
    answer = await probe.call("free-joint", joint=1)
    ctx.expect_done(answer, clause="free-joint.replies", expected="done once the joint is freed")
    discarded = await probe.call("here")
    ctx.expect_done(
        discarded,
        clause="free-joint.awaits-next-packet",
        expected="an empty done: the packet after free joint is not executed",
    )
    await expect_here_served(ctx, probe, "Here served normally once the joint is un-freed")


@case("server.free-joint.bad-joint", clauses=["free-joint.data"], technique="negative", hazard="motion")
async def free_joint_bad(ctx: CaseContext) -> None:
    """Free joint 0 or 7 (outside 1..degrees of freedom) is a command error."""
    probe = await ctx.connect()
    await power_on(ctx, probe)
    for joint in (0, 7):
        answer = await probe.call("free-joint", joint=joint)
        expect_refusal(ctx, answer, clause="free-joint.data", what=f"free joint {joint}")


HAND_AMOUNTS: Final = (0, 1, 0, 2, 0, 0o400, 0, 0o177777)
"""Open or close hand's amounts the hand-amounts case sends: each but 0 opens a binary hand, 0o400 with
a low byte of zero, 0o177777 with every bit set."""


@case("server.hand.amounts", clauses=["hand.data"], hazard="motion")
async def hand_amounts(ctx: CaseContext) -> None:
    """Open or close hand takes any 16-bit amount, answered with done: 0 closes a binary hand and every
    other value opens it (2, 0o400, 0o177777 as well as 1)."""
    probe = await ctx.connect()
    await power_on(ctx, probe)
    for amount in HAND_AMOUNTS:
        answer = await probe.call("hand", amount=amount)
        ctx.expect_done(
            answer, clause="hand.data", expected=f"done for open or close hand of amount {amount}"
        )


# ------------------------------------------------------------------ configuration and per-connection state
CONFIGURATIONS: Final = ((1, "lefty"), (0, "righty"))
"""Set configuration's values (bit 0: 1 lefty, 0 righty)."""
SOLUTION_TOL_DEG: Final = 0.01
"""Two solve-forwards answers within this of each other, joint by joint, are the same solution."""
REACH_TOL_MM: Final = 0.05


def _same(a: tuple[float, ...], b: tuple[float, ...]) -> bool:
    return max(abs(x - y) for x, y in zip(a, b, strict=True)) <= SOLUTION_TOL_DEG


async def _solve(ctx: CaseContext, probe: Probe, pose: list[float]) -> tuple[float, ...] | None:
    """Solve forwards of ``pose`` near :data:`CONFIGURATION_SEED` (None when refused)."""
    answer = await probe.call("solve-forwards", transform=pose, current=list(CONFIGURATION_SEED))
    return floats(answer) if answer.is_response else None


async def _seed_pose(ctx: CaseContext, probe: Probe) -> list[float]:
    """The transform of :data:`CONFIGURATION_SEED`, by the target's own solve backwards."""
    back = await probe.call("solve-backwards", joints=list(CONFIGURATION_SEED))
    require_response(ctx, back, "solve backwards of the seed angles")
    return list(floats(back))


@case("server.motion.configuration", clauses=["set-configuration.effect"], hazard="config")
async def configuration(ctx: CaseContext) -> None:
    """After set configuration lefty and righty, solve forwards of one transform near one joint vector
    gives two different solutions, each reaching the transform (erratum set-configuration)."""
    probe = await ctx.connect()
    pose = await _seed_pose(ctx, probe)
    solutions: dict[str, tuple[float, ...]] = {}
    for value, name in CONFIGURATIONS:
        answer = await probe.call("set-configuration", configuration=value)
        require_response(ctx, answer, f"set configuration {name}")
        solved = await _solve(ctx, probe, pose)
        if solved is None:
            ctx.not_judged(
                f"solve forwards of the seed's transform was refused after set configuration {name} "
                "(server.reply.solve-forwards judges it: the seed's angles are in range)"
            )
        back = await probe.call("solve-backwards", joints=list(solved))
        require_response(ctx, back, "solve backwards of a solution")
        off = math.dist(floats(back)[9:], pose[9:])
        ctx.expect(
            off <= length(ctx, REACH_TOL_MM),
            clause="set-configuration.effect",
            expected=f"the {name} solution reaching the transform",
            seen=f"{[round(q, 2) for q in solved]}, {off:.4g} {ctx.options.length_unit} from it",
        )
        solutions[name] = solved
    ctx.expect(
        not _same(solutions["lefty"], solutions["righty"]),
        clause="set-configuration.effect",
        expected="different solutions for lefty and righty (the seed's transform has both in range)",
        seen=f"both {[round(q, 2) for q in solutions['lefty']]}",
    )


RAISE_DEG: Final = 1.0
"""How far the configuration-side case raises joint 2 alone to see which way the hand goes."""
HAND_Z: Final = 11
"""Index of the hand's z in a transform's twelve floats (three columns of rotation, then position)."""


@case("server.motion.configuration-side", clauses=["set-configuration.lefty-side"], hazard="config")
async def configuration_side(ctx: CaseContext) -> None:
    """The solution solve forwards gives after set configuration lefty is lefty by geometry, and after
    righty righty: raising joint 2 alone by a degree (the target's solve backwards) lowers the hand in
    the lefty one and raises it in the righty one.  A target whose solutions do not differ is judged by
    server.motion.configuration."""
    probe = await ctx.connect()
    pose = await _seed_pose(ctx, probe)
    for value, name in CONFIGURATIONS:
        require_response(ctx, await probe.call("set-configuration", configuration=value), f"set {name}")
        solved = await _solve(ctx, probe, pose)
        if solved is None:
            ctx.not_judged(
                f"solve forwards of the seed's transform was refused after set configuration {name} "
                "(server.motion.configuration judges it)"
            )
        raised = list(solved)
        raised[1] += RAISE_DEG
        before = await probe.call("solve-backwards", joints=list(solved))
        after = await probe.call("solve-backwards", joints=raised)
        require_response(ctx, before, "solve backwards of the solution")
        require_response(ctx, after, "solve backwards of the solution with joint 2 raised")
        drop = floats(before)[HAND_Z] - floats(after)[HAND_Z]
        side = "lefty" if drop > 0 else "righty"
        ctx.expect(
            side == name,
            clause="set-configuration.lefty-side",
            expected=f"a {name} solution after set configuration {value} (raising joint 2 "
            f"{'lowers' if name == 'lefty' else 'raises'} the hand)",
            seen=f"{[round(q, 2) for q in solved]}: raising joint 2 by {RAISE_DEG:g} deg moves the hand "
            f"{-drop:+.2f} mm in z, a {side} solution",
        )


WAIST_TURN_DEG: Final = 15.0
"""How far the joint-order case turns element 1 of the joint vector alone."""
TURN_TOL_DEG: Final = 0.5
HAND_TOL_MM: Final = 0.5


@case("server.motion.joint-order", clauses=["joint-angles.reply"], hazard="motion", deadline=20.0)
async def joint_order(ctx: CaseContext) -> None:
    """Joint vectors start at the base: set joint angles with element 1 alone changed by 15 degrees turns
    the hand about the base's vertical axis (Here's position keeps its height and its distance from the
    axis and turns by 15 degrees), and joint angles then answers the changed element 1.  A server that
    reverses every joint vector consistently passes every check against its own solver, and fails here:
    its element 1 is the hand's joint."""
    probe = await ctx.connect()
    await power_on(ctx, probe)
    start = await read_floats(ctx, probe, "joint-angles")
    before = await read_floats(ctx, probe, "here")
    goal = list(start)
    goal[0] += WAIST_TURN_DEG if start[0] <= 0 else -WAIST_TURN_DEG
    require_response(ctx, await probe.call("set-joint-angles", joints=goal), "a move of element 1 alone")
    try:
        reached = await settle(ctx, probe, goal, within=10.0, tol=0.01)
        ctx.expect(
            reached is not None,
            clause="joint-angles.reply",
            expected=f"joint angles answering {[round(q, 2) for q in goal]} once the move ends",
            seen=f"{[round(q, 2) for q in await read_floats(ctx, probe, 'joint-angles')]}",
        )
        after = await read_floats(ctx, probe, "here")
        _judge_waist_turn(ctx, before[9:], after[9:], goal[0] - start[0])
    finally:
        await probe.call("set-joint-angles", joints=list(start))
        await settle(ctx, probe, start, within=10.0)


def _judge_waist_turn(ctx: CaseContext, p0: tuple[float, ...], p1: tuple[float, ...], turn: float) -> None:
    """The hand moved from ``p0`` to ``p1`` (mm) as a turn of ``turn`` degrees about the base's z axis."""
    radius0, radius1 = math.hypot(p0[0], p0[1]), math.hypot(p1[0], p1[1])
    turned = math.degrees(math.atan2(p1[1], p1[0]) - math.atan2(p0[1], p0[0]))
    turned = (turned + 180.0) % 360.0 - 180.0
    ctx.expect(
        abs(p1[2] - p0[2]) <= HAND_TOL_MM
        and abs(radius1 - radius0) <= HAND_TOL_MM
        and abs(abs(turned) - abs(turn)) <= TURN_TOL_DEG,
        clause="joint-angles.reply",
        expected=f"element 1 the waist: the hand turned {abs(turn):g} deg about the base's z axis, at the "
        "same height and distance from it",
        seen=f"hand from {[round(x, 1) for x in p0]} to {[round(x, 1) for x in p1]} mm: turned "
        f"{turned:+.2f} deg, height {p1[2] - p0[2]:+.2f} mm, distance from the axis "
        f"{radius1 - radius0:+.2f} mm",
    )


async def _set_up_state(
    ctx: CaseContext, probe: Probe, pose: list[float]
) -> tuple[tuple[float, ...], int | None]:
    """Set every per-connection setting away from a fresh connection's: a slow speed, both notifications,
    the configuration whose solution differs from the fresh one.  Returns the fresh solution of the seed's
    transform, and that configuration (None: none changes it)."""
    fresh = await _solve(ctx, probe, pose)
    if fresh is None:
        ctx.not_judged(
            "solve forwards of the seed's transform was refused (server.reply.solve-forwards judges it: "
            "the seed's angles are in range)"
        )
    flipped: int | None = None
    for value, _ in CONFIGURATIONS:
        if not (await probe.call("set-configuration", configuration=value)).is_response:
            break
        solved = await _solve(ctx, probe, pose)
        if solved is not None and not _same(solved, fresh):
            flipped = value
            break
    require_response(ctx, await probe.call("set-speed", factor=SLOW_FACTOR), "a slow speed factor")
    await ask_notifications(ctx, probe, 0b11)  # refused: there are none to keep
    return fresh, flipped


@case(
    "server.connect.fresh-state",
    clauses=["connect.per-connection-state"],
    hazard="motion",
    deadline=20.0,
    extensions=["request-notifications"],
)
async def fresh_state(ctx: CaseContext) -> None:
    """A connection that set a slow speed, both notifications and a configuration closes; the next one
    has none of them: no asynchronous report of its move, moves at the speed an explicit factor 1 gives,
    and solve forwards gives the solution a fresh connection gave (Part II §5: the main process sets these
    up per connection; erratum server-robot)."""
    first = await ctx.connect()
    pose = await _seed_pose(ctx, first)
    fresh, flipped = await _set_up_state(ctx, first, pose)
    await first.close()
    probe = await ctx.connect()
    await power_on(ctx, probe)
    await _small_move(ctx, probe, 1.0)
    await _wait_still(ctx, probe)
    reports = [
        p for p in [*probe.unsolicited, *await probe.drain(0.3)] if p.opcode == ServerOp.ASYNCHRONOUS_RESPONSE
    ]
    ctx.expect(
        not reports,
        clause="connect.per-connection-state",
        expected="no asynchronous response: the notifications the last connection asked for are not in force",
        seen=showing(reports[:1], f"{len(reports)} asynchronous response(s)"),
    )
    if flipped is None:
        ctx.note("set configuration changed no solution: the configuration is not judged")
    else:
        solved = await _solve(ctx, probe, pose)
        ctx.expect(
            solved is not None and _same(solved, fresh),
            clause="connect.per-connection-state",
            expected=f"solve forwards giving {[round(q, 2) for q in fresh]}, as on a fresh connection "
            "(no configuration set)",
            seen=f"{[round(q, 2) for q in solved] if solved else None}: the last connection's configuration",
        )
    notified = await ask_notifications(ctx, probe, SEGMENT_MASK)
    delay = await host_delay(ctx)
    default = await _timed_small_move(ctx, probe, -1.0, notified=notified)
    require_response(ctx, await probe.call("set-speed", factor=1.0), "speed factor 1")
    full = await _timed_small_move(ctx, probe, 1.0, notified=notified)
    delay = max(delay, await host_delay(ctx))
    ctx.note(f"1-degree move: {default:.3f} s at the fresh speed, {full:.3f} s at factor 1")
    # As in speed_scales: the host's delays may lengthen either timing by up to `delay`.
    _expect_fresh_speed(ctx, default, full, delay)


def _expect_fresh_speed(ctx: CaseContext, default: float, full: float, delay: float) -> None:
    held = ctx.expect(
        default - delay <= full * SPEED_MATCH,
        clause="connect.per-connection-state",
        expected=f"the fresh connection moving at factor 1 (the move within {SPEED_MATCH:g} times the time "
        "at an explicit factor 1)",
        seen=f"{default:.3f} s against {full:.3f} s (the last connection left factor {SLOW_FACTOR:g})",
    )
    if held and default > (full - delay) * SPEED_MATCH:
        not_judged_for_load(
            ctx,
            f"connect.per-connection-state (speed): a move took {default:.3f} s at the fresh speed and "
            f"{full:.3f} s at factor 1, and the case's own timers ended up to {delay * 1000:.1f} ms late: "
            "too close to tell; an idle host would judge it",
        )
