"""Floats in replies (E NOTE): PDP-11 F format, values that make sense, solve forwards and backwards
agreeing with Here and Joint angles."""

from __future__ import annotations

import math
import struct

from manip.conformance.cases._support import expect_response, floats, read_floats
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext

ORTHO_TOL = 1e-3
POSITION_TOL_MM = 0.05
ANGLE_TOL_DEG = 0.05


def _dot(a: tuple[float, ...], b: tuple[float, ...]) -> float:
    return sum(x * y for x, y in zip(a, b, strict=True))


@case(
    "server.float.here-consistent",
    clauses=[
        "float.format",
        "float.range",
        "float.not-finite",
        "here.transform",
        "joint-angles.reply",
        "solve-backwards.data",
    ],
)
async def here_consistent(ctx: CaseContext) -> None:
    """Here is a rotation plus a position, and Solve backwards of the joint angles gives it back."""
    probe = await ctx.connect()
    pose = await read_floats(ctx, probe, "here")
    joints = await read_floats(ctx, probe, "joint-angles")
    ctx.expect(
        len(pose) == 12 and all(math.isfinite(v) for v in pose),
        clause="here.transform",
        expected="12 finite floats",
        actual=pose,
    )
    n, o, a = pose[0:3], pose[3:6], pose[6:9]
    worst = max(
        abs(_dot(n, n) - 1),
        abs(_dot(o, o) - 1),
        abs(_dot(a, a) - 1),
        abs(_dot(n, o)),
        abs(_dot(n, a)),
        abs(_dot(o, a)),
    )
    ctx.expect(
        worst < ORTHO_TOL,
        clause="float.format",
        expected="N, O, A orthonormal (floats decoded as PDP-11 F, sign/exponent word first)",
        actual=f"deviation {worst:.3g} in {[round(v, 4) for v in pose[:9]]}",
    )
    ctx.expect(
        all(abs(q) <= 720.0 for q in joints),
        clause="joint-angles.reply",
        expected="six joint angles in degrees",
        actual=joints,
    )
    answer = await probe.call("solve-backwards", joints=list(joints))
    expect_response(ctx, answer, clause="solve-backwards.data", expected="a transform")
    solved = floats(answer)
    err = max(abs(x - y) for x, y in zip(solved[9:], pose[9:], strict=True))
    ctx.expect(
        err < POSITION_TOL_MM,
        clause="solve-backwards.data",
        expected="solve backwards of the joint angles equal to Here",
        actual=f"positions differ by {err:.3f} mm: {solved[9:]} vs {pose[9:]}",
    )


@case("server.float.solve-round-trip", clauses=["solve-forwards.data", "solve-backwards.data"])
async def solve_round_trip(ctx: CaseContext) -> None:
    """Solve forwards of Here near the current angles returns angles reaching the same pose."""
    probe = await ctx.connect()
    pose = await read_floats(ctx, probe, "here")
    joints = await read_floats(ctx, probe, "joint-angles")
    answer = await probe.call("solve-forwards", transform=list(pose), current=list(joints))
    expect_response(ctx, answer, clause="solve-forwards.data", expected="six joint angles")
    solved = floats(answer)
    back = await probe.call("solve-backwards", joints=list(solved))
    expect_response(ctx, back, clause="solve-backwards.data", expected="a transform")
    again = floats(back)
    err = max(abs(x - y) for x, y in zip(again, pose, strict=True))
    ctx.expect(
        err < POSITION_TOL_MM,
        clause="solve-forwards.data",
        expected="the solved angles reaching the transform",
        actual=f"off by {err:.4f}",
    )


@case("server.float.dirty-zero", clauses=["float.dirty-zero"])
async def dirty_zero(ctx: CaseContext) -> None:
    """Zeros in replies are clean (all bits 0), never exponent 0 with fraction bits."""
    probe = await ctx.connect()
    for op in ("here", "joint-angles"):
        answer = await probe.call(op)
        payload = answer.payload
        for i in range(0, len(payload) - 3, 4):
            w0, w1 = struct.unpack_from("<HH", payload, i)
            exponent = (w0 >> 7) & 0xFF
            ctx.expect(
                exponent != 0 or (w0 & 0x7F == 0 and w1 == 0 and not w0 & 0x8000),
                clause="float.dirty-zero",
                expected="a clean zero",
                actual=f"float words {w0:04x} {w1:04x} in {op}",
                data=answer.data,
            )
