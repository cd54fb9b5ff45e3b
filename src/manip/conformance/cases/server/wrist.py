"""Read forces (Part II §6.3): its values, in ounces and ounce-inches, following what acts on the hand;
and a Cougar that does not answer (erratum wrist-timeout): the main process gives up and answers a
non-fatal error, and goes on serving.

The target's world silences the Cougar (condition ``silent-wrist``) and pushes the hand
(``wrist-force``): the embedded server's world always, another target's with ``--world``; without a world
those cases are not judged, nor on a target that serves no wrist (the wrist opcodes are Puma
extensions)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Final

from manip.conformance.cases._support import error_of, floats, no_wrist, require_response
from manip.conformance.judge.checks import WirePacket, word
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext, Probe
from manip.conformance.suite.world import SilentWrist, WristForce
from manip.spec.constants import ANSWER_OPS, ServerOp

WEIGHT_OZ: Final = 64.0
"""The object set weight tells Cougar of, which the hand does not hold (ounces)."""
PUSH_OZ: Final = 48.0
"""The force the world puts on the hand along its z axis, the tool axis (ounces): along the axis
through the sensor and the compliance centre, so that it adds no torque about the centre."""
TWIST_OZ_IN: Final = 96.0
"""The torque the world puts on the hand about its z axis (ounce-inches)."""
ABSOLUTE_TOL: Final = 2.0
RELATIVE_TOL: Final = 0.1
"""A reading matches what acts on the hand within 2 oz (oz-in) and 10 % of it: the wrist's filter,
its 12-bit gauges and its gravity model each leave a little; pounds are 16 times off."""
STEADY_S: Final = 5.0
STEADY_TOL: Final = 0.5
"""The wrist's reading holds still once no component moves more than this in a quarter second."""
GIVE_UP_S: Final = 5.0
"""How long the case waits for the answers: the erratum's wrist timeout is 0.5 s, and the 1985 guide's
'reasonable amount of time' is taken to be well within ten times that."""


@case(
    "server.wrist.no-answer",
    clauses=["wrist.no-answer"],
    hazard="read-only",
    deadline=15.0,
    extensions=["wrist-version", "read-forces"],
)
async def no_answer(ctx: CaseContext) -> None:
    """Read forces while Cougar is silent is answered with a non-fatal error within a few seconds, and
    the Joint angles request sent right after it is answered after it."""
    probe = await ctx.connect()
    await _require_wrist(ctx, probe)
    await probe.close()
    async with ctx.arranged(SilentWrist()):
        probe = await ctx.connect()
        await _judge_silence(ctx, probe)


async def _judge_silence(ctx: CaseContext, probe: Probe) -> None:
    """Read forces, then joint angles, while Cougar is silent: a non-fatal E error, then the answer."""
    forces = await probe.send("read-forces")
    angles = await probe.send("joint-angles")
    answers: list[WirePacket] = []
    deadline = ctx.clock() + GIVE_UP_S
    while len(answers) < 2 and (left := deadline - ctx.clock()) > 0:
        packet = await probe.next_packet(left)
        if packet is None:
            break
        if packet.opcode in ANSWER_OPS:
            answers.append(packet)
    numbers = [word(p.data, 0) for p in answers]
    seen = ", ".join(f"0{p.opcode:o} for #{n}" for p, n in zip(answers, numbers, strict=True)) or "nothing"
    ctx.expect(
        bool(answers) and answers[0].opcode == ServerOp.NON_FATAL_ERROR and numbers[0] == forces,
        clause="wrist.no-answer",
        expected=f"read forces (#{forces}) answered with a non-fatal error (202) within {GIVE_UP_S:g} s "
        "while Cougar is silent",
        seen=str(seen),
    )
    error = error_of(answers[0])
    ctx.expect(
        error is not None and error.error.severity in ("E", "BE"),
        clause="wrist.no-answer",
        expected="a non-fatal error of severity E (the connection goes on)",
        seen=answers[0],
    )
    ctx.expect(
        len(answers) == 2 and numbers[1] == angles and answers[1].opcode == ServerOp.RESPONSE,
        clause="wrist.no-answer",
        expected=f"joint angles (#{angles}), sent after it, answered after it",
        seen=str(seen),
    )


async def _require_wrist(ctx: CaseContext, probe: Probe) -> None:
    """A target that serves no wrist (the opcodes are Puma extensions) leaves the case not judged."""
    version = await probe.call("wrist-version")
    if not version.is_response:
        ctx.not_judged(no_wrist(version))


async def _quiet_wrist(ctx: CaseContext, probe: Probe) -> None:
    """No gauge offsets, frame vector or weight another case left: the readings start from the wrist's."""
    require_response(ctx, await probe.call("set-gauge-offsets", offsets=[0] * 8), "zero gauge offsets")
    require_response(ctx, await probe.call("set-frame-vector", offset=[0.0] * 3), "no frame vector")
    require_response(ctx, await probe.call("set-weight", weight=0.0, cg=[0.0] * 3), "no weight")


async def steady_forces(ctx: CaseContext, probe: Probe, what: str) -> tuple[float, ...]:
    """Read forces until the reading holds still (Cougar's filter takes a few ticks to follow a change);
    not judged when it never does within :data:`STEADY_S`."""
    last = await _read_forces(ctx, probe)
    deadline = ctx.clock() + STEADY_S
    while ctx.clock() < deadline:
        await probe.drain(0.25)
        now = await _read_forces(ctx, probe)
        if max(abs(a - b) for a, b in zip(now, last, strict=True)) < STEADY_TOL:
            return now
        last = now
    ctx.not_judged(f"the wrist's reading {what} did not hold still within {STEADY_S:g} s")


async def _read_forces(ctx: CaseContext, probe: Probe) -> tuple[float, ...]:
    """Read forces, waiting as long as a silent Cougar may take to be given up on (a Cougar that slept
    while nothing needed it catches up first)."""
    answer = await probe.call("read-forces", timeout=max(GIVE_UP_S, ctx.options.reply_timeout))
    require_response(ctx, answer, "a normal reply to read forces")
    return floats(answer)


def _near(seen: float, wanted: float) -> bool:
    return abs(seen - wanted) <= ABSOLUTE_TOL + RELATIVE_TOL * abs(wanted)


PUSH_CONDITION: Final = WristForce((0.0, 0.0, PUSH_OZ), (0.0, 0.0, TWIST_OZ_IN))
"""The world's push on the hand that server.wrist.force-push reads forces under."""
PUSH_WRENCH: Final = (0.0, 0.0, PUSH_OZ, 0.0, 0.0, TWIST_OZ_IN)
"""What the reading changes by while the world pushes the hand (:data:`PUSH_OZ` along its z axis,
:data:`TWIST_OZ_IN` about it): forces in ounces, torques in ounce-inches."""


def push_shown(rest: Sequence[float], pushed: Sequence[float], released: Sequence[float]) -> bool:
    """Whether the reading while the world pushed differs from those before and after
    (``read-forces.current``)."""
    return tuple(pushed) not in (tuple(rest), tuple(released))


def push_sized(change: Sequence[float]) -> bool:
    """Whether the reading changed by :data:`PUSH_WRENCH` when the world pushed (``read-forces.units``)."""
    return len(change) == len(PUSH_WRENCH) and all(
        _near(c, w) for c, w in zip(change, PUSH_WRENCH, strict=True)
    )


def let_go(rest: Sequence[float], released: Sequence[float]) -> bool:
    """Whether the reading came back to ``rest`` once the world let go (``read-forces.current``)."""
    return len(rest) == len(released) and all(_near(b - a, 0.0) for a, b in zip(rest, released, strict=True))


def _shown(values: tuple[float, ...]) -> str:
    return "(" + ", ".join(f"{v:.2f}" for v in values) + ")"


@case(
    "server.wrist.force-weight",
    clauses=["read-forces.units"],
    hazard="config",
    deadline=20.0,
    extensions=["wrist-version", "set-gauge-offsets", "set-frame-vector", "set-weight", "read-forces"],
)
async def force_weight(ctx: CaseContext) -> None:
    """Set weight of a 64 oz object the hand does not hold changes the corrected force by 64 oz: Cougar
    subtracts the object's weight the hand does not feel (B.15 NEWWC, weights in ounces).  No world is
    needed, only a wrist."""
    probe = await ctx.connect()
    await _require_wrist(ctx, probe)
    await _quiet_wrist(ctx, probe)
    try:
        rest = await steady_forces(ctx, probe, "at rest")
        require_response(ctx, await probe.call("set-weight", weight=WEIGHT_OZ, cg=[0.0] * 3), "set weight")
        loaded = await steady_forces(ctx, probe, "after set weight")
    finally:
        await probe.call("set-weight", weight=0.0, cg=[0.0] * 3)
    change = [b - a for a, b in zip(rest[:3], loaded[:3], strict=True)]
    size = math.sqrt(sum(c * c for c in change))
    ctx.expect(
        _near(size, WEIGHT_OZ),
        clause="read-forces.units",
        expected=f"the corrected force changed by {WEIGHT_OZ:g} oz, the weight of the object set weight "
        "told of (ounces)",
        seen=f"changed by {size:.2f} (from {_shown(rest[:3])} to {_shown(loaded[:3])})"
        + (f": {WEIGHT_OZ / size:.1f} times too small" if 0 < size < WEIGHT_OZ / 2 else ""),
    )


@case(
    "server.wrist.force-push",
    clauses=["read-forces.units", "read-forces.current"],
    hazard="config",
    deadline=30.0,
    extensions=["wrist-version", "set-gauge-offsets", "set-frame-vector", "set-weight", "read-forces"],
)
async def force_push(ctx: CaseContext) -> None:
    """Read forces follows what acts on the hand: with the world pushing 48 oz along the hand's z axis and
    twisting 96 oz-in about it, the reading changes by just that (ounces and ounce-inches), and
    once the world lets go it comes back; three readings on one connection while the force changes.

    The target's world puts the wrench on the hand (``wrist-force``: the embedded server's world always,
    another target's with ``--world``); without a world the case is not judged."""
    probe = await ctx.connect()
    await _require_wrist(ctx, probe)
    await _quiet_wrist(ctx, probe)
    rest = await steady_forces(ctx, probe, "at rest")
    async with ctx.arranged(PUSH_CONDITION):
        pushed = await steady_forces(ctx, probe, "while the world pushed the hand")
    released = await steady_forces(ctx, probe, "once the world let go")
    ctx.expect(
        push_shown(rest, pushed, released),
        clause="read-forces.current",
        expected="each reading the force Cougar senses then: the one while the world pushed differing from "
        "those before and after",
        seen=f"at rest {_shown(rest)}, pushed {_shown(pushed)}, let go {_shown(released)}",
    )
    change = tuple(b - a for a, b in zip(rest, pushed, strict=True))
    wanted = PUSH_WRENCH
    ctx.expect(
        push_sized(change),
        clause="read-forces.units",
        expected=f"the reading changed by {_shown(wanted)}: {PUSH_OZ:g} oz along z and {TWIST_OZ_IN:g} "
        "oz-in about it, the wrench the world put on the hand",
        seen=f"changed by {_shown(change)}"
        + (f": {PUSH_OZ / change[2]:.1f} times too small" if 0 < change[2] < PUSH_OZ / 2 else ""),
    )
    ctx.expect(
        let_go(rest, released),
        clause="read-forces.current",
        expected=f"the reading back at rest, {_shown(rest)}, once the world let go",
        seen=str(_shown(released)),
    )
