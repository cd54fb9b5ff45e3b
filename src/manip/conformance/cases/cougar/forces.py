"""ADC8's integer filter and the conversion of gauges to forces (errata cougar-filter-rounding,
cougar-units)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from manip.conformance.cases.cougar._support import (
    clean,
    close_to,
    examine_region,
    expect_reply,
    fmt,
    int16,
    region_floats,
    settle,
)
from manip.conformance.cougar.probe import (
    CougarProbe,
    cougar_probe,
)
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext
from manip.cougar.memory import region


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
    """Each tick's filtered gauge reading is (u_k + u_k-1 + 6 Y_k-1) >> 3 exactly, also while it
    recovers from a deposited disturbance of 100 counts (erratum cougar-filter-rounding)."""
    raw, filtered = region("gauge_raw"), region("gauge_filtered")

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
            actual=f"ticks {got[0].tick} and {got[1].tick}",
        )
        return int16(got[0].data_words[1:]), int16(got[1].data_words[1:])

    async with cougar_probe(ctx) as probe:
        await clean(probe)
        await settle(probe)
        _, y0 = await sample()
        for i, reading in enumerate(y0):
            await probe.send("DPST", address=filtered.at(i), value=(reading - 100) & 0xFFFF)
        u_prev, y_prev = await sample()
        ctx.expect(
            y_prev == [y - 100 for y in y0],
            clause="cougar.memory",
            expected=f"the deposited filter state {[y - 100 for y in y0]}",
            actual=str(y_prev),
        )
        for k in range(12):
            u, y = await sample()  # the next tick
            want = [(u[i] + u_prev[i] + 6 * y_prev[i]) >> 3 for i in range(8)]
            ctx.expect(
                y == want,
                clause="cougar.adc8-filter",
                expected=f"tick {k + 1} after the disturbance: Y = (u + u_prev + 6 Y_prev) >> 3 = {want} "
                f"(u = {u}, u_prev = {u_prev}, Y_prev = {y_prev})",
                actual=f"Y = {y}",
            )
            u_prev, y_prev = u, y


def _expected_voltmat(calmat: Sequence[float], fv_mm: Sequence[float]) -> np.ndarray[Any, Any]:
    """The clause's conversion: -(10/2048) * calmat, torque rows taken about the compliance centre
    (tau - r x f, r in inches: erratum cougar-units)."""
    cal = np.array(calmat, dtype=np.float64).reshape(6, 8)
    r = np.array(fv_mm, dtype=np.float64) / 25.4
    torque = cal[3:] - np.cross(r, cal[:3].T).T
    out: np.ndarray[Any, Any] = -(10.0 / 2048.0) * np.vstack([cal[:3], torque])
    return out


@case(
    "cougar.forces.conversion",
    clauses=[
        "cougar.nfv-conversion",
        "cougar.rfrc.reply",
        "cougar.memory",
        "cougar.comint.partial-waits",
        "cougar.exmn.reply",
        "cougar.response.layout",
        "cougar.rraw.reply",
    ],
    hazard="config",
    deadline=8.0,
)
async def forces_conversion(ctx: CaseContext) -> None:
    """The conversion matrix is -(10/2048) x calibration with the compliance-centre transform; NFV
    changes only its torque rows; and raising one gauge offset by d changes the force Cougar reports
    by -voltmat[:, g] * d (the -1: forces are what the robot applies)."""
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        fv0 = await region_floats(ctx, probe, "fv")
        offsets0 = tuple(int16(await examine_region(ctx, probe, "gauge_offsets")))
        try:
            calmat = await region_floats(ctx, probe, "calmat")
            for fv in ((0.0, 0.0, 0.0), (30.0, -20.0, 100.0)):
                await probe.send("NFV", offset=fv)
                await probe.run(2)
                vm = np.array(await region_floats(ctx, probe, "voltmat")).reshape(6, 8)
                want = _expected_voltmat(calmat, fv)
                scale = float(np.abs(want).max()) or 1.0
                ctx.expect(
                    bool(np.allclose(vm, want, rtol=1e-5, atol=1e-6 * scale)),
                    clause="cougar.nfv-conversion",
                    expected=f"voltmat = -(10/2048) calmat with the torque rows about fv = {fv} mm: "
                    f"{fmt(want.reshape(-1)[:8])}...",
                    actual=f"{fmt(vm.reshape(-1)[:8])}... (largest difference "
                    f"{float(np.abs(vm - want).max()):.3g})",
                )
                if fv == (0.0, 0.0, 0.0):
                    force_rows = vm[:3].copy()
                else:
                    ctx.expect(
                        bool(np.array_equal(vm[:3], force_rows)),
                        clause="cougar.nfv-conversion",
                        expected="NFV leaves the force rows of voltmat unchanged",
                        actual=f"largest change {float(np.abs(vm[:3] - force_rows).max()):.3g}",
                    )
            await settle(probe)
            gauge = int(np.argmax(np.abs(vm).sum(axis=0)))
            delta = 100
            before = await _raw_and_forces(ctx, probe)
            shifted = list(offsets0)
            shifted[gauge] += delta
            await probe.send("WGOV", offsets=tuple(shifted))
            await probe.run(2)
            after = await _raw_and_forces(ctx, probe)
            offsets_delta = np.zeros(8)
            offsets_delta[gauge] = delta
            want_change = vm @ (np.array(after[0]) - np.array(before[0]) - offsets_delta)
            change = np.array(after[1]) - np.array(before[1])
            ctx.expect(
                close_to(list(change), list(want_change), rel=0.02, floor=0.05),
                clause="cougar.nfv-conversion",
                expected=f"gauge {gauge} offset +{delta} changes the force by voltmat (dY - d_offset) = "
                f"{fmt(want_change)}",
                actual=f"{fmt(change)}",
            )
        finally:
            await probe.send("WGOV", offsets=offsets0)
            await probe.send("NFV", offset=fv0)
            await probe.run(1)


async def _raw_and_forces(ctx: CaseContext, probe: CougarProbe) -> tuple[list[int], tuple[float, ...]]:
    """RRAW and RFRC answered in the same tick: the filtered readings and the force made from them."""
    await probe.send("RRAW")
    await probe.send("RFRC")
    raw = expect_reply(ctx, await probe.reply("RRAW"), "RAW", "cougar.rraw.reply", after="RRAW")
    forces = expect_reply(ctx, await probe.reply("RFRC"), "FORCES", "cougar.rfrc.reply", after="RFRC")
    ctx.expect(
        raw.tick == forces.tick,
        clause="cougar.comint.partial-waits",
        expected="RRAW and RFRC sent together answered in the same tick",
        actual=f"ticks {raw.tick} and {forces.tick}",
    )
    return int16(raw.data_words), forces.floats()
