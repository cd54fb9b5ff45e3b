"""NPR's compliance gains and RST (erratum cougar-compliance-equation), through properties any linear
law has."""

from __future__ import annotations

from typing import Any, Final

import numpy as np

from manip.arm import PUMA560_LEE, READY, forward
from manip.arm.units import MM_PER_UNIT
from manip.codecs.pdp11float import f_to_words
from manip.conformance.cases.cougar._support import (
    POSE_B,
    clean,
    examine_region,
    expect_close,
    expect_examine,
    expect_none,
    expect_reply,
    fmt,
    in_unit,
    mapped,
    peek_region,
    region_floats,
    settle,
)
from manip.conformance.cougar.probe import (
    CougarProbe,
    cougar_probe,
    floats_of,
    words_bytes,
)
from manip.conformance.judge.violation import showing
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext
from manip.cougar.memory import Region

# ------------------------------------------------------------------------------------------ NPR, RST
_THETA_ERROR: Final = (1.0, -1.0, 1.0, 2.0, -2.0, 2.0)
BJI_STEPS: Final = (1.0, 2.0, 3.0, 0.5, 1.5, 2.5)
"""Each joint's BJI as a multiple of the uniform one: a diagonal BJI scales joint i's NTD by its own."""
GAIN: Final = 5.0
"""K (oz/mm) and B (oz s/mm) steps: with the position error and rate difference used, their force
terms are ~100 oz, so gauge noise of a fraction of an ounce stays far inside the 2 % tolerance."""


async def _ntd(
    ctx: CaseContext,
    probe: CougarProbe,
    *,
    k: float,
    b: float,
    bji: float | tuple[float, ...],
    rate: float,
) -> tuple[float, ...]:
    """NTD for diagonal gains (K = k, B = b I, BJI = bji, or each joint's own) at READY with a fixed
    position error, after RST (so the output filter starts from rest whatever its constants)."""
    await probe.send("NK", k=(k,) * 6)
    await probe.send("NB", b=tuple(b if i % 7 == 0 else 0.0 for i in range(36)))
    await probe.send("NBJI", bji=bji if isinstance(bji, tuple) else (bji,) * 6)
    await probe.send("NFC", force=(0.0,) * 6)
    await probe.send("RST")
    expect_none(ctx, await probe.run(3), "cougar.word-link", "parameter commands have no response")
    commanded = tuple(a + e for a, e in zip(READY, _THETA_ERROR, strict=True))
    reply = await probe.call(
        "NPR", theta_sensed=READY, theta_commanded=commanded, rate_difference=(rate,) * 6
    )
    expect_reply(ctx, reply, "NTD", "cougar.npr.reply", after="NPR")
    values = reply.floats()
    ctx.expect_finite(
        values, 6, clause="cougar.npr.reply", expected="six finite floats", seen=showing(reply, fmt(values))
    )
    return values


@case(
    "cougar.npr.gains",
    clauses=["cougar.npr.reply", "cougar.response.layout", "cougar.word-link"],
    hazard="config",
    deadline=8.0,
)
async def npr_gains(ctx: CaseContext) -> None:
    """NTD answers the gains NK, NB and NBJI set: zero joint damping inverse gives zero; the part due
    to K (position error) and to B (rate difference) is non-zero and doubles when the gain doubles;
    doubling BJI doubles the whole answer, and each joint's element of BJI scales that joint's part alone
    (erratum cougar-compliance-equation)."""
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        await settle(probe)
        try:
            zero = await _ntd(ctx, probe, k=5.0, b=1.0, bji=0.0, rate=3.0)
            ctx.expect(
                all(abs(v) <= 1e-6 for v in zero),
                clause="cougar.npr.reply",
                expected="NTD all zero with BJI = 0",
                seen=fmt(zero),
            )
            bji = 0.01
            base = await _ntd(ctx, probe, k=0.0, b=0.0, bji=bji, rate=0.0)
            for gain, kw in (("K", "k"), ("B", "b")):
                rate = 3.0 if kw == "b" else 0.0
                one = await _ntd(ctx, probe, **{"k": 0.0, "b": 0.0, kw: GAIN}, bji=bji, rate=rate)
                two = await _ntd(ctx, probe, **{"k": 0.0, "b": 0.0, kw: 2 * GAIN}, bji=bji, rate=rate)
                rest = base if kw == "k" else await _ntd(ctx, probe, k=0.0, b=0.0, bji=bji, rate=rate)
                d1 = [x - y for x, y in zip(one, rest, strict=True)]
                d2 = [x - y for x, y in zip(two, rest, strict=True)]
                ctx.expect(
                    max(abs(v) for v in d1) > 1e-4,
                    clause="cougar.npr.reply",
                    expected=f"NTD to change when {gain} goes from 0 to {GAIN:g} (with a "
                    f"{'position error' if kw == 'k' else 'rate difference'})",
                    seen=f"{fmt(rest)} -> {fmt(one)}",
                )
                doubled = [2 * v for v in d1]
                expect_close(
                    ctx,
                    d2,
                    doubled,
                    rel=0.02,
                    clause="cougar.npr.reply",
                    expected=f"doubling {gain} doubles its part of NTD: {fmt(doubled)}",
                )
            one = await _ntd(ctx, probe, k=GAIN, b=0.0, bji=bji, rate=0.0)
            two = await _ntd(ctx, probe, k=GAIN, b=0.0, bji=2 * bji, rate=0.0)
            doubled = [2 * v for v in one]
            expect_close(
                ctx,
                two,
                doubled,
                rel=0.02,
                clause="cougar.npr.reply",
                expected=f"doubling BJI doubles NTD: {fmt(doubled)}",
            )
            each = tuple(bji * m for m in BJI_STEPS)
            own = await _ntd(ctx, probe, k=GAIN, b=0.0, bji=each, rate=0.0)
            want = [v * m for v, m in zip(one, BJI_STEPS, strict=True)]
            diagonal = f"BJI {fmt(each)} (diagonal: joint i's own element scales joint i)"
            expect_close(
                ctx,
                own,
                want,
                rel=0.02,
                clause="cougar.npr.reply",
                expected=f"{diagonal} gives NTD {fmt(want)}",
            )
        finally:
            await probe.send("NBJI", bji=(0.0,) * 6)
            await probe.send("RST")
            await probe.run(1)


@case(
    "cougar.rst.zeroes-velocities",
    clauses=[
        "cougar.rst",
        "cougar.memory",
        "cougar.exmn.reply",
        "cougar.npr.reply",
        "cougar.response.layout",
    ],
    hazard="config",
)
async def rst_zeroes_velocities(ctx: CaseContext) -> None:
    """After NPR with a rate difference, RST sets the rate difference, the filter state and the last
    NTD in memory to zero."""
    names = ("rate_difference", "dtheta_previous", "dtheta_filtered", "dtheta_out")
    objects = mapped(ctx, *names)
    rate = (1.0, 2.0, 3.0, -1.0, -2.0, -3.0)
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        await probe.send("NK", k=(1.0,) * 6)
        await probe.send("NBJI", bji=(0.01,) * 6)
        await probe.run(2)
        commanded = tuple(a + e for a, e in zip(READY, _THETA_ERROR, strict=True))
        reply = await probe.call("NPR", theta_sensed=READY, theta_commanded=commanded, rate_difference=rate)
        expect_reply(ctx, reply, "NTD", "cougar.npr.reply", after="NPR")
        stored = await region_floats(ctx, probe, objects[0])
        expect_close(
            ctx,
            stored,
            rate,
            rel=1e-6,
            floor=0.0,
            clause="cougar.memory",
            expected=f"NPR's rate difference in memory before RST: {fmt(rate)}",
        )
        await probe.send("RST")
        await probe.run(1)
        for name, obj in zip(names, objects, strict=True):
            words = await examine_region(ctx, probe, obj)
            values = floats_of(words)
            ctx.expect(
                all(v == 0.0 for v in values),
                clause="cougar.rst",
                expected=f"{name} zero after RST",
                seen=showing(words_bytes(words), fmt(values)),
            )
        await probe.send("NBJI", bji=(0.0,) * 6)
        await probe.run(1)


# ------------------------------------------------------------------------------------------ FILTER
FILTER_CON: Final = (0.5, -0.5, 1.0, 0.25)
"""con1..con4 deposited for the FILTER case: after RST the first NTD is (con1 con3 + con4) times the
compliance sample and, the sample unchanged, the second is (-con2 con1 con3 + con4) times it: 0.75 and
0.5 here, where a swap of con3 and con4 gives 1.125 and 1.0625."""


@case(
    "cougar.filter.output",
    clauses=["cougar.filter", "cougar.npr.reply", "cougar.response.layout", "cougar.word-link"],
    hazard="config",
    deadline=8.0,
)
async def filter_output(ctx: CaseContext) -> None:
    """FILTER (B.10) with constants deposited in Cougar's memory: with the defaults NTD is the compliance
    sample itself; with con1..con4 = 0.5, -0.5, 1, 0.25 two NPRs of the same sample after RST answer 0.75
    and then 0.5 times it (the filter's derivative term, then its decay)."""
    (con,) = mapped(ctx, "con")
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        await settle(probe)
        old = await peek_region(ctx, probe, con)
        try:
            sample = await _ntd(ctx, probe, k=GAIN, b=0.0, bji=0.01, rate=0.0)
            ctx.expect(
                max(abs(v) for v in sample) > 1e-3,
                clause="cougar.npr.reply",
                expected="a non-zero NTD for a position error with K and BJI set",
                seen=fmt(sample),
            )
            words = [w for c in FILTER_CON for w in f_to_words(c)]
            for i, w in enumerate(words):
                await probe.send("DPST", address=con.address + 2 * i, value=w)
            c1, c2, c3, c4 = FILTER_CON
            first = await _ntd(ctx, probe, k=GAIN, b=0.0, bji=0.01, rate=0.0)
            commanded = tuple(a + e for a, e in zip(READY, _THETA_ERROR, strict=True))
            reply = await probe.call(
                "NPR", theta_sensed=READY, theta_commanded=commanded, rate_difference=(0.0,) * 6
            )
            expect_reply(ctx, reply, "NTD", "cougar.npr.reply", after="NPR")
            second = reply.floats()
            for label, got, factor in (
                ("first", first, c1 * c3 + c4),
                ("second", second, -c2 * c1 * c3 + c4),
            ):
                want = [factor * v for v in sample]
                after_rst = f"the {label} NTD after RST with con = {FILTER_CON}"
                expect_close(
                    ctx,
                    got,
                    want,
                    rel=0.02,
                    clause="cougar.filter",
                    expected=f"{after_rst}: {factor:g} x the sample, {fmt(want)}",
                )
        finally:
            for i, w in enumerate(old):
                await probe.send("DPST", address=con.address + 2 * i, value=w)
            await probe.send("NBJI", bji=(0.0,) * 6)
            await probe.send("RST")
            await probe.run(1)


# ------------------------------------------------------------------------------------------ NB, Jᵀ
JT_FLOATS: Final = 72
"""J then Jᵀ: the floats a Jacobian buffer holds from its start when Jᵀ follows J (B.2)."""
DAMPING: Final = tuple(
    1.0 if i == j else 0.8 if j == (i + 1) % 6 else -0.5 if j == (i + 3) % 6 else 0.0
    for i in range(6)
    for j in range(6)
)
"""A damping matrix far from its transpose (row after row): ones on the diagonal, 0.8 just right of it
and -0.5 three columns on, each row turned."""
NB_RATE: Final = (3.0, -2.0, 1.5, 4.0, -3.0, 2.5)
NB_BJI: Final = 0.001


async def _front_jacobian(ctx: CaseContext, probe: CougarProbe) -> tuple[np.ndarray[Any, Any], Region]:
    """J (6x6) of the front buffer, and the buffer's map object."""
    front, *buffers = mapped(ctx, "jacob_front", "jbuf0", "jbuf1")
    (which,) = await expect_examine(ctx, probe, front.address, 1)
    buffer = buffers[which & 1]
    j = await expect_examine(ctx, probe, buffer.address, 72)
    if len(j) != 72:
        ctx.fail(
            "EXMN did not return the Jacobian: the case cannot go on",
            clause="cougar.exmn.reply",
            expected=f"72 words at {buffer.address:#o}",
            seen=f"{len(j)} words",
        )
    return np.array(floats_of(j)).reshape(6, 6), buffer


async def _ntd_at(ctx: CaseContext, probe: CougarProbe, damping: tuple[float, ...]) -> np.ndarray[Any, Any]:
    """NTD at POSE_B with no position error, the rate difference NB_RATE, K = 0 and B = ``damping``."""
    await probe.send("NK", k=(0.0,) * 6)
    await probe.send("NB", b=damping)
    await probe.send("NBJI", bji=(NB_BJI,) * 6)
    await probe.send("NFC", force=(0.0,) * 6)
    await probe.send("RST")
    await probe.run(2)
    reply = await probe.call("NPR", theta_sensed=POSE_B, theta_commanded=POSE_B, rate_difference=NB_RATE)
    expect_reply(ctx, reply, "NTD", "cougar.npr.reply", after="NPR")
    return np.array(reply.floats() or (0.0,) * 6)


@case(
    "cougar.npr.damping-matrix",
    clauses=[
        "cougar.nb-row-order",
        "cougar.npr.reply",
        "cougar.memory",
        "cougar.exmn.reply",
        "cougar.response.layout",
    ],
    hazard="config",
    deadline=8.0,
)
async def npr_damping_matrix(ctx: CaseContext) -> None:
    """NB's 36 elements are B row after row (erratum cougar-compliance-equation): with a B far from
    symmetric, the damping part of NTD is -BJI Jᵀ B J (rate difference), worked out here from the
    Jacobian Cougar holds (its front buffer)."""
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        await settle(probe, POSE_B)
        try:
            j, _ = await _front_jacobian(ctx, probe)
            rest = await _ntd_at(ctx, probe, (0.0,) * 36)
            damped = await _ntd_at(ctx, probe, DAMPING)
            b = np.array(DAMPING).reshape(6, 6)
            want = -NB_BJI * (j.T @ (b @ (j @ np.array(NB_RATE))))
            got = damped - rest
            scale = float(np.abs(want).max())
            for i in range(6):
                ctx.expect_near(
                    got[i],
                    want[i],
                    0.01 * scale + 1e-6,
                    clause="cougar.nb-row-order",
                    expected=f"joint {i + 1}: NB's part of NTD = -BJI (Jᵀ B J rate)[{i}] = {want[i]:.5g} "
                    f"for B row after row (within 1 % of {scale:.3g})",
                    seen=f"{got[i]:.5g} (B transposed would give "
                    f"{float(-NB_BJI * (j.T @ (b.T @ (j @ np.array(NB_RATE))))[i]):.5g})",
                )
        finally:
            await probe.send("NB", b=(0.0,) * 36)
            await probe.send("NBJI", bji=(0.0,) * 6)
            await probe.send("RST")
            await probe.send("SEN", theta_sensed=READY)
            await probe.run(1)


@case(
    "cougar.jacob.transpose-stored",
    clauses=["cougar.jacob-transpose", "cougar.memory", "cougar.exmn.reply", "cougar.response.layout"],
    hazard="config",
)
async def jacob_transpose_stored(ctx: CaseContext) -> None:
    """The 36 floats after the Jacobian in its buffer are its transpose, stored explicitly (B.2), each
    row its own check; not judged where the map declares the buffer with J alone."""
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        await settle(probe, POSE_B)
        try:
            j, buffer = await _front_jacobian(ctx, probe)
            if buffer.count < JT_FLOATS:
                ctx.not_judged(
                    f"the memory map declares {buffer.name} with {buffer.count} floats, and Jᵀ follows J "
                    f"in the {JT_FLOATS} from its start (B.2): declare the buffer's size to judge it"
                )
            await _transpose_follows(ctx, probe, j, buffer)
        finally:
            await probe.send("SEN", theta_sensed=READY)
            await probe.run(1)


async def _transpose_follows(
    ctx: CaseContext, probe: CougarProbe, j: np.ndarray[Any, Any], buffer: Region
) -> None:
    words = await expect_examine(ctx, probe, buffer.at(36), 72)
    jt = np.array(floats_of(words) if len(words) == 72 else (float("nan"),) * 36).reshape(6, 6)
    for row in range(6):
        ctx.expect(
            bool(np.allclose(jt[row], j.T[row], rtol=1e-6, atol=1e-9)),
            clause="cougar.jacob-transpose",
            expected=f"row {row + 1} of the floats after J ({buffer.name}, from {buffer.at(36):#o}) = "
            f"column {row + 1} of J: {fmt(j.T[row])}",
            seen=fmt(jt[row]),
        )


# ------------------------------------------------------------------------------------------ J's values
JACOB_FV_MM: Final = (25.0, -40.0, 120.0)
"""The compliance centre the Jacobian check moves to, in millimetres (sent in the run's length unit): off
every hand axis, so the centre's part of each translational row shows."""
JACOB_STEP_DEG: Final = 1.0e-3
"""Half the step of the central differences that work J out: their truncation error is ~ step² (in
radians) of J, 1e-10 of it, and their rounding ~ 1e-13 mm per degree."""
JACOB_REL: Final = 1.0e-4
"""How far an element of J may be from the one worked out, as a fraction of the largest element of its
block (translational or rotational rows).  Cougar stores J as PDP-11 F_floating (24-bit significand: each
float within 6e-8 of its value) and computes it in that arithmetic, a few dozen products and sums of link
lengths with sines and cosines good to their last bit: well under 1e-6 of the block's largest element.
1e-4 leaves a hundredfold margin, while a wrong sign, a link length mixed up or degrees taken as radians
moves elements by a sizeable part of the block."""
Matrix = np.ndarray[Any, Any]


def worked_jacobian(theta_deg: tuple[float, ...], fv_mm: tuple[float, ...]) -> Matrix:
    """J (mm/deg, deg/deg) at ``theta_deg`` about the point ``fv_mm`` of the hand (hand axes), worked out
    from the arm model's poses alone: each column is the central difference, over ±JACOB_STEP_DEG of its
    joint, of the point's position and of the hand's turn, both in hand axes at ``theta_deg``."""
    rotation = forward(theta_deg, PUMA560_LEE).matrix[:3, :3]
    fv = np.array(fv_mm, dtype=np.float64)
    columns = []
    for joint in range(6):
        ends = []
        for sign in (1.0, -1.0):
            q = list(theta_deg)
            q[joint] += sign * JACOB_STEP_DEG
            ends.append(forward(tuple(q), PUMA560_LEE).matrix)
        plus, minus = ends
        moved = (plus[:3, 3] + plus[:3, :3] @ fv) - (minus[:3, 3] + minus[:3, :3] @ fv)
        turn = plus[:3, :3] @ minus[:3, :3].T  # I + [w]x (2 step in radians), w the base-axes turn rate
        w = np.array([turn[2, 1] - turn[1, 2], turn[0, 2] - turn[2, 0], turn[1, 0] - turn[0, 1]]) / 2.0
        columns.append(
            np.concatenate([rotation.T @ moved, rotation.T @ w / np.radians(1.0)]) / (2.0 * JACOB_STEP_DEG)
        )
    return np.array(columns).T


@case(
    "cougar.jacob.values",
    clauses=["cougar.jacob-values", "cougar.memory", "cougar.exmn.reply", "cougar.response.layout"],
    hazard="config",
)
async def jacob_values(ctx: CaseContext) -> None:
    """The Jacobian in the front buffer, after SEN of a pose away from READY and NFV of a centre off every
    axis, is the one worked out here from the arm model's poses at those angles (erratum
    cougar-compliance-equation: about the compliance centre, hand axes; the run's length unit per degree
    and degrees per degree), each row its own check."""
    (fv_obj,) = mapped(ctx, "fv")
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        fv0 = await region_floats(ctx, probe, fv_obj)
        try:
            await probe.send("NFV", offset=in_unit(ctx, JACOB_FV_MM))
            await settle(probe, POSE_B)
            j, buffer = await _front_jacobian(ctx, probe)
            want = worked_jacobian(POSE_B, JACOB_FV_MM)
            want[:3] /= MM_PER_UNIT[ctx.options.length_unit]
            unit = f"{ctx.options.length_unit}/deg"
            for rows, units in ((range(3), unit), (range(3, 6), "deg/deg")):
                tolerance = JACOB_REL * float(np.abs(want[rows.start : rows.stop]).max())
                for row in rows:
                    ctx.expect(
                        bool(np.all(np.abs(j[row] - want[row]) <= tolerance)),
                        clause="cougar.jacob-values",
                        expected=f"row {row + 1} of J ({buffer.name}, {units}) at {fmt(POSE_B)} about "
                        f"{fmt(JACOB_FV_MM)} mm = {fmt(want[row])} (each within {tolerance:.2g})",
                        seen=fmt(j[row]),
                    )
        finally:
            await probe.send("NFV", offset=fv0)
            await probe.send("SEN", theta_sensed=READY)
            await probe.run(1)
