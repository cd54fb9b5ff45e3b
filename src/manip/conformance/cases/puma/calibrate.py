"""Calibrate wrist (Part III §8.3, erratum ``calibrate-wrist``): the judge answers Read Raw Gauges with
readings made of chosen offsets plus a gravity load that depends on the pose the Puma last reported, so
only readings taken in poses whose loads cancel average to the offsets."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final

import numpy as np

from manip.arm.kinematics import PUMA600, forward
from manip.codecs.messages import decode_reply
from manip.conformance.cases._support import read_floats, require_response, settle
from manip.conformance.cases.puma._support import SEGMENT_WITHIN, begin, session
from manip.conformance.puma.judge import SENSED, CougarScript, Heard
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext
from manip.spec import SPEC
from manip.spec.constants import CougarCommand

GAUGES: Final = 8
LOAD: Final = 400
"""Gauge counts per unit of gravity along each hand axis (the gravity load is up to this big)."""
CANCEL: Final = 0.02
"""Two poses' gravity directions in the hand cancel when their sum is shorter than this."""
HORIZONTAL: Final = 0.02
"""The tool axis is horizontal when its world z component is smaller than this (about 1.1 degrees)."""
SAME_DEG: Final = 0.5
"""Two readings of a joint within this many degrees are the same angle."""


def gravity_in_hand(pose: Sequence[float]) -> np.ndarray:
    """The unit gravity vector in the hand's frame at ``pose`` (PUMA 600 kinematics)."""
    rotation = np.asarray(forward(tuple(pose), PUMA600.geometry).matrix)[:3, :3]
    return np.asarray(rotation.T @ np.array([0.0, 0.0, -1.0]))


def _poses_of_reads(heard: Sequence[Heard]) -> list[tuple[float, ...]]:
    """For each Read Raw Gauges, the sensed angles the Puma last sent before it."""
    pose: tuple[float, ...] | None = None
    out: list[tuple[float, ...]] = []
    for h in heard:
        msg = h.msg
        if msg is None:
            continue
        if msg.code in SENSED:
            sensed = msg.values["theta_sensed"]
            assert isinstance(sensed, tuple)
            pose = tuple(float(v) for v in sensed)
        elif msg.code == CougarCommand.RRAW and pose is not None:
            out.append(pose)
    return out


@case("puma.calibrate-wrist", clauses=["puma.calibrate-wrist"], hazard="motion", deadline=60.0)
async def calibrate_wrist(ctx: CaseContext) -> None:
    """Calibrate wrist reads the gauges in two poses whose gravity loads cancel and sets their mean as
    the gauge offsets (Write Gauge Offset Vector, and the reply)."""
    probe = await session(ctx, notify=None)
    r = ctx.random
    offsets = [r.randint(-300, 300) for _ in range(GAUGES)]
    load = np.array([[r.uniform(-LOAD, LOAD) for _ in range(3)] for _ in range(GAUGES)])

    def gauges(pose: Sequence[float]) -> list[int]:
        reading = np.asarray(offsets) + load @ gravity_in_hand(pose)
        return [round(float(v)) for v in reading]

    judge, mark = begin(ctx, CougarScript(gauges=gauges))
    answer = await probe.call("calibrate-wrist")
    require_response(ctx, answer, "calibrate-wrist answered")
    await judge.wait_ticks(3, 5.0)
    heard = judge.since(mark)
    poses = _poses_of_reads(heard)
    loads = [gravity_in_hand(p) for p in poses]
    cancelling = any(float(np.linalg.norm(a + b)) < CANCEL for a in loads for b in loads)
    ctx.expect(
        cancelling,
        clause="puma.calibrate-wrist",
        expected="Read Raw Gauges in two poses whose gravity loads on the wrist cancel",
        seen=f"{len(poses)} readings, gravity in the hand: "
        + "; ".join(sorted({"(" + ", ".join(f"{v:.3f}" for v in g) + ")" for g in loads})[:4]),
    )
    wgov = judge.commands(mark, CougarCommand.WGOV)
    sent = wgov[-1].msg.values["offsets"] if wgov and wgov[-1].msg else None
    ctx.expect(
        isinstance(sent, tuple) and all(abs(a - b) <= 1 for a, b in zip(sent, offsets, strict=True)),
        clause="puma.calibrate-wrist",
        expected=f"Write Gauge Offset Vector with the gauges' offsets {offsets} (within 1 count)",
        seen=str(wgov[-1]) if wgov else "no WGOV sent",
    )
    replied = decode_reply(answer.data, SPEC.request("calibrate-wrist")).values.get("offsets")
    ctx.expect(
        replied == sent,
        clause="puma.calibrate-wrist",
        expected=f"calibrate-wrist answered with the offsets set: {sent}",
        seen=answer,
    )


def _half_turn_apart(first: Sequence[float], other: Sequence[float]) -> bool:
    """``other`` is ``first`` with joint 6 turned half a turn, joints 1-5 the same."""
    turned = abs((other[5] - first[5]) % 360.0 - 180.0) <= SAME_DEG
    return turned and all(abs(a - b) <= SAME_DEG for a, b in zip(first[:5], other[:5], strict=True))


@case(
    "puma.calibrate-wrist.positions",
    clauses=["puma.calibrate-wrist.positions"],
    hazard="motion",
    deadline=60.0,
)
async def calibrate_wrist_positions(ctx: CaseContext) -> None:
    """Calibrate wrist reads the gauges first with the tool axis horizontal, then with joint 6 turned half
    a turn from there (joints 1-5 unchanged), and brings the arm back to where it started."""
    probe = await session(ctx, notify=None)
    start = await read_floats(ctx, probe, "joint-angles")
    judge, mark = begin(ctx, CougarScript(gauges=lambda pose: [0] * GAUGES))
    answer = await probe.call("calibrate-wrist")
    require_response(ctx, answer, "calibrate-wrist answered")
    poses = _poses_of_reads(judge.since(mark))
    first = poses[0] if poses else None
    tilt = float(np.asarray(forward(tuple(first), PUMA600.geometry).matrix)[2, 2]) if first else None
    ctx.expect(
        tilt is not None and abs(tilt) < HORIZONTAL,
        clause="puma.calibrate-wrist.positions",
        expected=f"the first Read Raw Gauges with the tool axis horizontal (world z below {HORIZONTAL:g})",
        seen=f"read at {_rounded(first)}: tool axis z {tilt}" if first else "no Read Raw Gauges",
    )
    others = sorted({tuple(round(v, 2) for v in p) for p in poses if p != first})
    ctx.expect(
        first is not None and any(_half_turn_apart(first, p) for p in poses),
        clause="puma.calibrate-wrist.positions",
        expected="a second pose with joint 6 half a turn from the first, joints 1-5 unchanged",
        seen=f"first pose {_rounded(first)}, others {others[:3]}",
    )
    back = await settle(ctx, probe, start, within=SEGMENT_WITHIN * ctx.options.deadline_scale, tol=SAME_DEG)
    now = await read_floats(ctx, probe, "joint-angles")
    ctx.expect(
        back is not None,
        clause="puma.calibrate-wrist.positions",
        expected=f"the arm back where it started, {_rounded(start)}",
        seen=f"it stays at {_rounded(now)}",
    )


def _rounded(pose: Sequence[float] | None) -> tuple[float, ...] | None:
    return None if pose is None else tuple(round(v, 2) for v in pose)
