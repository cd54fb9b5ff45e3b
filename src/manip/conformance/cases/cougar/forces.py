"""ADC8's integer filter and the conversion of gauges to forces (errata cougar-filter-rounding,
cougar-units)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Final

import numpy as np

from manip.arm import READY
from manip.arm.units import MM_PER_UNIT
from manip.conformance.cases.cougar._support import (
    POSE_B,
    SETTLE_TICKS,
    clean,
    examine_region,
    expect_reply,
    fmt,
    in_unit,
    int16,
    mapped,
    read_forces,
    region_floats,
    settle,
)
from manip.conformance.cougar.probe import (
    CougarProbe,
    cougar_probe,
)
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext
from manip.cougar.memory import Region


# ------------------------------------------------------------------------------------------ ADC8, forces
@case(
    "cougar.adc8.integer-filter",
    clauses=[
        "cougar.adc8-filter",
        "cougar.memory",
        "cougar.comint.partial-waits",
        "cougar.exmn.reply",
        "cougar.response.layout",
    ],
    hazard="config",
)
async def adc8_integer_filter(ctx: CaseContext) -> None:
    """Each tick's filtered gauge reading is (u_k + u_k-1 + 6 Y_k-1) / 8 rounded one way or the other
    (the shift's floor, or to nearest), also while it recovers from a deposited disturbance of 100
    counts; and, settled, it stands within 3 counts of its input (erratum cougar-filter-rounding)."""
    raw, filtered = mapped(ctx, "gauge_raw", "gauge_filtered")

    async def sample() -> tuple[list[int], list[int]]:
        """u_k and Y_k of one tick: both EXMNs run in the same COMINT, after that tick's ADC8."""
        await probe.send("EXMN", address=raw.address, count=raw.words)
        await probe.send("EXMN", address=filtered.address, count=filtered.words)
        got = [await probe.reply("EXMN of gauge_raw"), await probe.reply("EXMN of gauge_filtered")]
        for reply, r in zip(got, (raw, filtered), strict=True):
            expect_reply(ctx, reply, "EXMN-DATA", "cougar.exmn.reply", after="EXMN")
            ctx.expect(
                reply.data_words[:1] == (r.words,),
                clause="cougar.exmn.reply",
                expected=f"{r.words} words of {r.name}",
                seen=reply,
            )
        ctx.expect(
            got[0].tick == got[1].tick,
            clause="cougar.comint.partial-waits",
            expected="two EXMNs sent together answered in the same tick",
            seen=f"ticks {got[0].tick} and {got[1].tick}",
        )
        return int16(got[0].data_words[1:]), int16(got[1].data_words[1:])

    async with cougar_probe(ctx) as probe:
        await clean(probe)
        await settle(probe, POSE_B)  # a load whose counts are not multiples of 8
        _, y0 = await sample()
        for i, reading in enumerate(y0):
            await probe.send("DPST", address=filtered.at(i), value=(reading - 100) & 0xFFFF)
        u_prev, y_prev = await sample()
        ctx.expect(
            y_prev == [y - 100 for y in y0],
            clause="cougar.memory",
            expected=f"the deposited filter state {[y - 100 for y in y0]}",
            seen=str(y_prev),
        )
        for k in range(12):
            u, y = await sample()  # the next tick
            for i in range(8):  # each gauge its own check
                total = u[i] + u_prev[i] + 6 * y_prev[i]
                low, high = total >> 3, -(-total >> 3)  # the quotient's floor and ceiling
                ctx.expect(
                    low <= y[i] <= high,
                    clause="cougar.adc8-filter",
                    expected=f"tick {k + 1} after the disturbance, gauge {i}: "
                    f"Y = (u + u_prev + 6 Y_prev) / 8 = ({u[i]} + {u_prev[i]} + 6 x {y_prev[i]}) / 8 = "
                    f"{total / 8:g}, rounded: {low}" + (f" or {high}" if high != low else ""),
                    seen=f"Y = {y[i]}",
                )
            u_prev, y_prev = u, y
        await probe.run(SETTLE_TICKS)
        await _settles_near(ctx, sample)
        await probe.send("SEN", theta_sensed=READY)
        await probe.run(1)


SETTLE_SAMPLES: Final = 8
"""Ticks the settled filter is watched for its standing error."""
ROUNDING_BIAS: Final = 3
"""Counts a settled reading may stand off a constant input: floor((6 d) / 8) = d for d = -1, -2, -3, so
the shift's floor stops short by up to 3; rounding to nearest stands within 2 (erratum
cougar-filter-rounding)."""


async def _settles_near(ctx: CaseContext, sample: Any) -> None:
    """Once settled on a constant input, each gauge's filtered reading stands within 3 counts of its
    sample, averaged over a few ticks (a count of noise allowed): the filter's unity DC gain but for
    its rounding."""
    errors = [[0] * 8 for _ in range(SETTLE_SAMPLES)]
    for k in range(SETTLE_SAMPLES):
        u, y = await sample()
        errors[k] = [y[i] - u[i] for i in range(8)]
    for i in range(8):
        mean = sum(row[i] for row in errors) / SETTLE_SAMPLES
        ctx.expect(
            abs(mean) <= ROUNDING_BIAS + 1,
            clause="cougar.adc8-filter",
            expected=f"gauge {i} settled: the filtered reading within {ROUNDING_BIAS} counts of the sample "
            "(unity DC gain but for the division's rounding; a count of noise allowed)",
            seen=f"Y - u = {[row[i] for row in errors]} (mean {mean:.3g})",
        )


def _expected_voltmat(calmat: Sequence[float], fv_inch: Sequence[float]) -> np.ndarray[Any, Any]:
    """The clause's conversion: -(10/2048) * calmat, torque rows taken about the compliance centre
    (tau - r x f, r in inches since torques are in ounce-inches: erratum cougar-units)."""
    cal = np.array(calmat, dtype=np.float64).reshape(6, 8)
    r = np.array(fv_inch, dtype=np.float64)
    torque = cal[3:] - np.cross(r, cal[:3].T).T
    out: np.ndarray[Any, Any] = -(10.0 / 2048.0) * np.vstack([cal[:3], torque])
    return out


FV_MM: Final = (30.0, -20.0, 100.0)
"""The frame vector NFV sends, in millimetres (sent in the run's length unit)."""
OFFSET_STEP: Final = 100
"""Counts one gauge offset is raised by."""
COUNTS_SLACK: Final = 4
"""Counts a settled filtered reading may differ by: the filter's rounding (erratum
cougar-filter-rounding: up to 3 below) and a count of gauge noise."""


@case(
    "cougar.forces.conversion",
    clauses=[
        "cougar.nfv-conversion",
        "cougar.rfrc.reply",
        "cougar.memory",
        "cougar.exmn.reply",
        "cougar.response.layout",
    ],
    hazard="config",
    deadline=8.0,
)
async def forces_conversion(ctx: CaseContext) -> None:
    """The conversion matrix is -(10/2048) x calibration with the compliance-centre transform (the frame
    vector in the run's length unit, --length-unit); NFV changes only its torque rows; and, once the
    filter has settled, raising one gauge offset by d changes the force Cougar reports by
    -voltmat[:, g] * d (the -1: forces are what the robot applies), whether the offsets are subtracted
    before the filter (§8.3) or after it."""
    fv_obj, offsets_obj, calmat_obj, voltmat_obj = mapped(ctx, "fv", "gauge_offsets", "calmat", "voltmat")
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        fv0 = await region_floats(ctx, probe, fv_obj)
        offsets0 = tuple(int16(await examine_region(ctx, probe, offsets_obj)))
        try:
            calmat = await region_floats(ctx, probe, calmat_obj)
            vm = await _voltmat_follows_fv(ctx, probe, calmat, voltmat_obj)
            await _offset_step(ctx, probe, vm, offsets0)
        finally:
            await probe.send("WGOV", offsets=offsets0)
            await probe.send("NFV", offset=fv0)
            await probe.run(1)


async def _voltmat_follows_fv(
    ctx: CaseContext, probe: CougarProbe, calmat: Sequence[float], voltmat: Region
) -> np.ndarray[Any, Any]:
    """voltmat for a zero frame vector and for FV_MM, each row block its own check; the last one."""
    inches_per_unit = MM_PER_UNIT[ctx.options.length_unit] / 25.4
    force_rows: np.ndarray[Any, Any] | None = None
    vm = np.zeros((6, 8))
    for fv in ((0.0, 0.0, 0.0), in_unit(ctx, FV_MM)):
        await probe.send("NFV", offset=fv)
        await probe.run(2)
        vm = np.array(await region_floats(ctx, probe, voltmat)).reshape(6, 8)
        want = _expected_voltmat(calmat, [v * inches_per_unit for v in fv])
        scale = float(np.abs(want).max()) or 1.0
        for rows, what in ((slice(0, 3), "force rows"), (slice(3, 6), "torque rows")):
            ctx.expect(
                bool(np.allclose(vm[rows], want[rows], rtol=1e-5, atol=1e-6 * scale)),
                clause="cougar.nfv-conversion",
                expected=f"voltmat's {what} = -(10/2048) calmat about fv = {fmt(fv)} "
                f"{ctx.options.length_unit}: {fmt(want[rows].reshape(-1)[:8])}...",
                seen=f"{fmt(vm[rows].reshape(-1)[:8])}... (largest difference "
                f"{float(np.abs(vm[rows] - want[rows]).max()):.3g})",
            )
        if force_rows is None:
            force_rows = vm[:3].copy()
        else:
            ctx.expect(
                bool(np.array_equal(vm[:3], force_rows)),
                clause="cougar.nfv-conversion",
                expected="NFV leaves the force rows of voltmat unchanged",
                seen=f"largest change {float(np.abs(vm[:3] - force_rows).max()):.3g}",
            )
    return vm


async def _offset_step(
    ctx: CaseContext, probe: CougarProbe, vm: np.ndarray[Any, Any], offsets0: Sequence[int]
) -> None:
    """Raise the offset of the gauge that weighs most by OFFSET_STEP: once settled, the force moves by
    -voltmat[:, g] * OFFSET_STEP (each of the six its own check)."""
    await settle(probe)
    gauge = int(np.argmax(np.abs(vm).sum(axis=0)))
    before = await read_forces(ctx, probe)
    shifted = list(offsets0)
    shifted[gauge] += OFFSET_STEP
    await probe.send("WGOV", offsets=tuple(shifted))
    await probe.run(SETTLE_TICKS)
    after = await read_forces(ctx, probe)
    want = -vm[:, gauge] * OFFSET_STEP
    slack = np.abs(vm).sum(axis=1) * COUNTS_SLACK
    for i in range(6):
        change = after[i] - before[i]
        ctx.expect(
            abs(change - want[i]) <= slack[i] + 0.02 * abs(want[i]),
            clause="cougar.nfv-conversion",
            expected=f"gauge {gauge} offset +{OFFSET_STEP} moves force[{i}] by -voltmat[{i}, {gauge}] x "
            f"{OFFSET_STEP} = {want[i]:.4g} (within {slack[i]:.3g}: {COUNTS_SLACK} counts)",
            seen=f"{change:.4g} ({before[i]:.4g} -> {after[i]:.4g})",
        )


RRAW_SLACK: Final = 4
"""Counts a settled RRAW reading may move by when nothing physical changed: the filter's rounding (up to
3, erratum cougar-filter-rounding) and a count of noise."""


async def _raw_gauges(ctx: CaseContext, probe: CougarProbe) -> list[int]:
    reply = expect_reply(ctx, await probe.call("RRAW"), "RAW", "cougar.rraw.reply", after="RRAW")
    return int16(reply.data_words)


@case(
    "cougar.rraw.before-offsets",
    clauses=[
        "cougar.rraw.before-offsets",
        "cougar.rraw.reply",
        "cougar.exmn.reply",
        "cougar.response.layout",
    ],
    hazard="config",
    deadline=8.0,
)
async def rraw_before_offsets(ctx: CaseContext) -> None:
    """RRAW reports the gauges as read, before WGOV's offsets are subtracted: once settled, raising every
    offset by 100 counts leaves each of the eight readings where it was, whether RRAW reports the
    samples or the filtered readings."""
    (offsets_obj,) = mapped(ctx, "gauge_offsets")
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        offsets0 = tuple(int16(await examine_region(ctx, probe, offsets_obj)))
        try:
            await settle(probe, POSE_B)
            before = await _raw_gauges(ctx, probe)
            await probe.send("WGOV", offsets=tuple(o + OFFSET_STEP for o in offsets0))
            await probe.run(SETTLE_TICKS)
            after = await _raw_gauges(ctx, probe)
            for i, (b, a) in enumerate(zip(before, after, strict=True)):
                ctx.expect_near(
                    a,
                    b,
                    RRAW_SLACK,
                    clause="cougar.rraw.before-offsets",
                    expected=f"gauge {i}: the same raw reading after every offset rose by {OFFSET_STEP} "
                    f"(within {RRAW_SLACK} counts; WGOV's vector is subtracted from the raw readings)",
                    seen=f"{b} -> {a}",
                )
        finally:
            await probe.send("WGOV", offsets=offsets0)
            await probe.send("SEN", theta_sensed=READY)
            await probe.run(1)
