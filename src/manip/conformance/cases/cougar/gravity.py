"""GRAVITY's point-mass model judged by value (B.8, Table 1 NEWWC, B.14 NEWFV): the force and torque of
an object at two orientations of the hand, a guard on the corrected torque, and the model redone when
the frame vector changes (erratum cougar-units for the frame, units and sign).

The expected values are worked out here from the 1985 guide's model, never taken from the Cougar: an
object of weight W whose centre of gravity is c from the compliance centre (NEWWC: "the offset from the
frame vector") loads the hand with f = Rᵀ·(0, 0, -W) and τ = c × f, R being the hand's orientation at
the angles last sent (the arm model's end frame, the Puma 560's, as the Cougar's Jacobian is); forces in
ounces, torques in ounce-inches.  Cougar subtracts what it believes gravity does, so telling it of an
object the hand does not hold moves the force it reports by exactly that load (the forces are the ones
the robot applies: erratum cougar-units).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final

import numpy as np
import numpy.typing as npt

from manip.arm import PUMA560_LEE, READY, forward
from manip.arm.units import MM_PER_UNIT
from manip.conformance.cases.cougar._support import (
    POSE_B,
    clean,
    expect_reply,
    fmt,
    guard_trips,
    guard_words,
    in_unit,
    mapped,
    read_forces,
    region_floats,
    settle,
)
from manip.conformance.cougar.probe import CougarProbe, cougar_probe
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext

OBJECT_OZ: Final = 48.0
"""The weight of the object Cougar is told of (NEWWC) and the hand does not hold."""
OBJECT_CG_MM: Final = (40.0, -25.0, 90.0)
"""Its centre of gravity from the compliance centre, in millimetres (sent in the run's length unit):
off every axis, so each torque component has its own part."""
FV_MM: Final = (30.0, -20.0, 100.0)
"""The frame vector the NFV check moves the compliance centre to, in millimetres."""
SLACK_OZ: Final = 0.5
"""Ounces (or ounce-inches) a compared component may differ by besides 2 % of the largest: a couple of
gauge counts through the conversion, and the filter's rounding (erratum cougar-filter-rounding)."""
REL: Final = 0.02
COMPONENTS: Final = ("fx", "fy", "fz", "tx", "ty", "tz")
Vector = npt.NDArray[np.float64]


def object_load(theta_deg: Sequence[float], weight_oz: float, cg_inch: Sequence[float]) -> Vector:
    """The wrench (oz, oz-in; hand axes) of a point mass ``weight_oz`` at ``cg_inch`` from the compliance
    centre, the hand at ``theta_deg``: the 1985 guide's model, worked out here."""
    rotation = np.array(forward(tuple(theta_deg), PUMA560_LEE).rotation, dtype=np.float64)
    force = rotation.T @ np.array([0.0, 0.0, -weight_oz])
    return np.concatenate([force, np.cross(np.array(cg_inch, dtype=np.float64), force)])


def _close(got: float, want: float, scale: float) -> bool:
    return abs(got - want) <= REL * scale + SLACK_OZ


def _inches(ctx: CaseContext, mm: Sequence[float]) -> list[float]:
    """A length given in mm, as sent in the run's unit and then read in inches."""
    per_unit = MM_PER_UNIT[ctx.options.length_unit] / 25.4
    return [v * per_unit for v in in_unit(ctx, mm)]


async def _with_object(ctx: CaseContext, probe: CougarProbe) -> tuple[Vector, Vector]:
    """The forces with no object, then with the object: each two ticks after its NEWWC."""
    await probe.send("NEWWC", weight=0.0, cg=(0.0, 0.0, 0.0))
    await probe.run(2)
    bare = np.array(await read_forces(ctx, probe))
    await probe.send("NEWWC", weight=OBJECT_OZ, cg=in_unit(ctx, OBJECT_CG_MM))
    await probe.run(2)
    loaded = np.array(await read_forces(ctx, probe))
    return bare, loaded


@case(
    "cougar.gravity.point-mass",
    clauses=["cougar.gravity", "cougar.guard-corrected-force", "cougar.rfrc.reply", "cougar.response.layout"],
    hazard="config",
    deadline=8.0,
)
async def gravity_point_mass(ctx: CaseContext) -> None:
    """At READY and at a second orientation (SEN), telling Cougar of a 48 oz object with its centre of
    gravity off every axis moves all six components of the force it reports by the object's load,
    f = Rᵀ(0, 0, -W) and τ = cg × f, worked out from the 1985 guide's point-mass model; and a guard along
    that torque trips at half of it and not at one and a half times it."""
    cg_inch = _inches(ctx, OBJECT_CG_MM)
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        try:
            for label, pose in (("READY", READY), ("the second pose", POSE_B)):
                await settle(probe, pose)
                bare, loaded = await _with_object(ctx, probe)
                want = object_load(pose, OBJECT_OZ, cg_inch)
                scale = float(np.abs(want).max())
                for i, name in enumerate(COMPONENTS):
                    change = float(loaded[i] - bare[i])
                    ctx.expect(
                        _close(change, float(want[i]), scale),
                        clause="cougar.gravity",
                        expected=f"at {label}, an object of {OBJECT_OZ:g} oz at cg {fmt(cg_inch)} in moves "
                        f"{name} by {want[i]:.4g} (Rᵀ(0, 0, -W), cg × f; within {REL:.0%} of {scale:.3g} "
                        f"+ {SLACK_OZ})",
                        seen=f"{change:.4g} ({bare[i]:.4g} -> {loaded[i]:.4g})",
                    )
            await _guard_on_torque(ctx, probe, bare, want)
        finally:
            await clean(probe)
            await probe.send("NEWWC", weight=0.0, cg=(0.0, 0.0, 0.0))
            await probe.send("SEN", theta_sensed=READY)
            await probe.run(1)


async def _guard_on_torque(ctx: CaseContext, probe: CougarProbe, bare: Vector, want: Vector) -> None:
    """With the object in the model, a guard along its expected torque tests the corrected force: one at
    half the torque above the bare reading trips, one at one and a half times it does not."""
    torque = want[3:]
    size = float(np.linalg.norm(torque))
    dvec = (0.0, 0.0, 0.0, *(float(v) / size for v in torque))
    base = float(np.dot(bare, dvec))
    await probe.send_words(guard_words(3, dvec, base + 0.5 * size))
    await probe.send_words(guard_words(4, dvec, base + 1.5 * size))
    trips = guard_trips(await probe.run(3))
    ctx.expect(
        ("GUARD-CONTINUE", 3) in trips,
        clause="cougar.guard-corrected-force",
        expected=f"guard 3 along the object's torque, tol {base + 0.5 * size:.4g} (half its {size:.4g} oz-in "
        "above the bare reading), tripping on the corrected force",
        seen=str(trips) if trips else "no trip",
    )
    ctx.expect(
        all(index != 4 for _, index in trips),
        clause="cougar.guard-corrected-force",
        expected=f"guard 4 along it, tol {base + 1.5 * size:.4g} (one and a half times the torque), quiet",
        seen=str(trips),
    )


@case(
    "cougar.gravity.nfv-redoes-model",
    clauses=[
        "cougar.nfv-conversion",
        "cougar.gravity",
        "cougar.rfrc.reply",
        "cougar.exmn.reply",
        "cougar.response.layout",
    ],
    hazard="config",
    deadline=8.0,
)
async def gravity_nfv_redoes_model(ctx: CaseContext) -> None:
    """NFV alone (no NEWWC after it) redoes the gravity model (B.14): with no object and nothing
    touching, what Cougar reports is one wrench, so moving the compliance centre by r leaves the force
    as it was and makes the torque τ - r × f; a model left about the old centre adds r × the hand's
    weight to it."""
    (fv_obj,) = mapped(ctx, "fv")
    r_inch = np.array(_inches(ctx, FV_MM))
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        fv0 = await region_floats(ctx, probe, fv_obj)
        try:
            await probe.send("NEWWC", weight=0.0, cg=(0.0, 0.0, 0.0))
            await probe.send("NFV", offset=(0.0, 0.0, 0.0))
            await settle(probe, POSE_B)
            before = np.array(await read_forces(ctx, probe))
            await probe.send("NFV", offset=in_unit(ctx, FV_MM))
            await probe.run(2)
            after = np.array(await read_forces(ctx, probe))
            want = np.concatenate([before[:3], before[3:] - np.cross(r_inch, before[:3])])
            scale = float(np.abs(want).max())
            for i, name in enumerate(COMPONENTS):
                ctx.expect(
                    _close(float(after[i]), float(want[i]), scale),
                    clause="cougar.nfv-conversion",
                    expected=f"after NFV {fmt(in_unit(ctx, FV_MM))} {ctx.options.length_unit}, {name} = "
                    f"{want[i]:.4g} (the same wrench about the new centre: force unchanged, τ - r × f)",
                    seen=f"{after[i]:.4g} (before NFV {before[i]:.4g})",
                )
        finally:
            await probe.send("NFV", offset=fv0)
            await probe.send("SEN", theta_sensed=READY)
            await probe.run(1)


BJI: Final = 0.01
"""The joint accommodation of the compliance check: NTD = BJI Jᵀ (F_commanded - F) with K and B zero."""
NOISE_FACTOR: Final = 20.0
"""How far above the noise of two like NPRs the commanded force's effect on NTD must be for the check
of the corrected force to mean anything."""


async def _ntd_at_rest(ctx: CaseContext, probe: CougarProbe, commanded_force: Sequence[float]) -> Vector:
    """NTD for NPR at READY with the arm where it is commanded (no position error, no rate), after RST
    (the output filter at rest), the commanded force set to ``commanded_force``."""
    await probe.send("NFC", force=tuple(commanded_force))
    await probe.send("RST")
    await probe.run(2)
    reply = await probe.call("NPR", theta_sensed=READY, theta_commanded=READY, rate_difference=(0.0,) * 6)
    values = expect_reply(ctx, reply, "NTD", "cougar.npr.reply", after="NPR").floats()
    ctx.expect_finite(values, 6, clause="cougar.npr.reply", expected="six finite floats", seen=fmt(values))
    return np.array(values if len(values) == 6 else (0.0,) * 6, dtype=np.float64)


@case(
    "cougar.gravity.compliance-corrected",
    clauses=[
        "cougar.compliance-corrected-force",
        "cougar.npr.reply",
        "cougar.rfrc.reply",
        "cougar.response.layout",
    ],
    hazard="config",
    deadline=8.0,
)
async def gravity_compliance_corrected(ctx: CaseContext) -> None:
    """NPR's compliance equation works on the gravity-corrected force (B.8): with only BJI set (K and B
    zero, the arm where it is commanded), telling Cougar of an object the hand does not hold changes NTD
    as lowering the commanded force by the object's load (the change RFRC shows) does."""
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        try:
            await probe.send("NK", k=(0.0,) * 6)
            await probe.send("NB", b=(0.0,) * 36)
            await probe.send("NBJI", bji=(BJI,) * 6)
            await probe.send("NEWWC", weight=0.0, cg=(0.0, 0.0, 0.0))
            await settle(probe, READY)
            bare_force = np.array(await read_forces(ctx, probe))
            bare = await _ntd_at_rest(ctx, probe, (0.0,) * 6)
            again = await _ntd_at_rest(ctx, probe, (0.0,) * 6)
            await probe.send("NEWWC", weight=OBJECT_OZ, cg=in_unit(ctx, OBJECT_CG_MM))
            await probe.run(2)
            load = np.array(await read_forces(ctx, probe)) - bare_force
            loaded = await _ntd_at_rest(ctx, probe, (0.0,) * 6)
            await probe.send("NEWWC", weight=0.0, cg=(0.0, 0.0, 0.0))
            await probe.run(2)
            shifted = await _ntd_at_rest(ctx, probe, tuple(float(v) for v in -load))
            _expect_same_ntd(ctx, loaded, shifted, bare, load)
            noise = float(np.abs(again - bare).max())
            ctx.expect(
                float(np.abs(shifted - bare).max()) > NOISE_FACTOR * noise,
                clause="cougar.npr.reply",
                expected=f"NTD moving with the commanded force (F_commanded in the compliance equation, "
                f"erratum cougar-compliance-equation) by more than {NOISE_FACTOR:g} times its noise "
                f"({noise:.2g})",
                seen=f"NFC {fmt(-load)} gave NTD {fmt(shifted)}, NFC 0 gave {fmt(bare)}",
            )
        finally:
            await probe.send("NBJI", bji=(0.0,) * 6)
            await probe.send("NFC", force=(0.0,) * 6)
            await probe.send("NEWWC", weight=0.0, cg=(0.0, 0.0, 0.0))
            await probe.send("RST")
            await probe.run(1)


def _expect_same_ntd(ctx: CaseContext, loaded: Vector, shifted: Vector, bare: Vector, load: Vector) -> None:
    """NTD with the object told of equals NTD with no object and the commanded force lowered by its load,
    within 2 % of that load's effect on NTD plus the gauge noise's share of it."""
    effect = float(np.abs(shifted - bare).max())
    slack = effect * (REL + SLACK_OZ / max(float(np.abs(load).max()), SLACK_OZ))
    for i, name in enumerate(("joint 1", "joint 2", "joint 3", "joint 4", "joint 5", "joint 6")):
        ctx.expect(
            abs(float(loaded[i] - shifted[i])) <= slack,
            clause="cougar.compliance-corrected-force",
            expected=f"NTD {name} with the object told of (NEWWC {OBJECT_OZ:g} oz) = NTD with none and the "
            f"commanded force lowered by its load {fmt(load)}: {shifted[i]:.4g} (within {slack:.2g})",
            seen=f"{loaded[i]:.4g} (with no object and no commanded force: {bare[i]:.4g})",
        )
