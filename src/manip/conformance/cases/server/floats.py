"""Floats in replies (E NOTE): PDP-11 F format, values that make sense, solve forwards and backwards
agreeing with Here and Joint angles."""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence

from manip.conformance.cases._support import floats, length, read_floats
from manip.conformance.judge.violation import showing
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext, Probe
from manip.spec.constants import ServerOp

ORTHO_TOL = 1e-3
REACH_MM = 5000.0
"""Far beyond any PUMA's reach: a position further out is no position Solve backwards can give."""
TINY = 1e-38
"""Degrees whose sines are below 2^-128: the transform's entries then underflow and must be clean zeros."""
TINY_WRIST = (0.0, 0.0, 0.0, TINY, TINY, TINY)
"""Joint angles whose transform's rotation differs from that of all joints at 0 by at most 3 sin(TINY
degrees), about 5e-40: below 2^-128, so where that rotation has a zero, this one has a zero too."""
HUGE = 1.0e38
"""Near the top of the F range (1.7e38)."""
POSITION_TOL_MM = 0.05


def _dot(a: Sequence[float], b: Sequence[float]) -> float:
    return sum(x * y for x, y in zip(a, b, strict=True))


def rotation_error(pose: Sequence[float]) -> float:
    """How far N, O, A (the first nine floats, column by column) are from orthonormal."""
    n, o, a = pose[0:3], pose[3:6], pose[6:9]
    return max(
        abs(_dot(n, n) - 1),
        abs(_dot(o, o) - 1),
        abs(_dot(a, a) - 1),
        abs(_dot(n, o)),
        abs(_dot(n, a)),
        abs(_dot(o, a)),
    )


def by_rows(pose: Sequence[float]) -> tuple[float, ...]:
    """The twelve floats of a transform sent row by row (Nx Ox Ax Px Ny ...), in column-major order."""
    return tuple(pose[row * 4 + column] for column in range(4) for row in range(3))


def sent_by_rows(pose: Sequence[float]) -> bool:
    """Whether Here's twelve floats are no rotation read column by column but one read row by row (Nx
    Ox Ax Px Ny ...): Here broke its order, not the floats."""
    return len(pose) == 12 and rotation_error(pose) >= ORTHO_TOL and rotation_error(by_rows(pose)) < ORTHO_TOL


@case(
    "server.float.here-consistent",
    clauses=[
        "float.format",
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
    ctx.expect_finite(pose, 12, clause="here.transform", expected="12 finite floats", seen=str(pose))
    worst = rotation_error(pose)
    row_major = sent_by_rows(pose)
    ctx.expect(
        not row_major,
        clause="here.transform",
        expected="the transform column by column: Nx Ny Nz Ox Oy Oz Ax Ay Az Px Py Pz",
        seen=f"read row by row (Nx Ox Ax Px Ny ...) the floats are a rotation: {[round(v, 4) for v in pose]}",
    )
    ctx.expect(
        worst < ORTHO_TOL or row_major,
        clause="float.format",
        expected="N, O, A orthonormal (floats decoded as PDP-11 F, sign/exponent word first)",
        seen=f"deviation {worst:.3g} in {[round(v, 4) for v in pose[:9]]}",
    )
    if row_major:
        pose = by_rows(pose)  # solve backwards is judged against the transform Here meant
    ctx.expect(
        all(abs(q) <= 720.0 for q in joints),
        clause="joint-angles.reply",
        expected="six joint angles in degrees",
        seen=str(joints),
    )
    answer = await probe.call("solve-backwards", joints=list(joints))
    ctx.expect_response(answer, clause="solve-backwards.data", expected="a transform")
    solved = floats(answer)
    err = max(abs(x - y) for x, y in zip(solved[9:], pose[9:], strict=True))
    ctx.expect(
        err < length(ctx, POSITION_TOL_MM),
        clause="solve-backwards.data",
        expected="solve backwards of the joint angles equal to Here",
        seen=f"positions differ by {err:.4g} {ctx.options.length_unit}: {solved[9:]} vs {pose[9:]}",
    )


@case("server.float.solve-round-trip", clauses=["solve-forwards.data", "solve-backwards.data"])
async def solve_round_trip(ctx: CaseContext) -> None:
    """Solve forwards of Here near the current angles returns angles reaching the same pose."""
    probe = await ctx.connect()
    pose = await read_floats(ctx, probe, "here")
    joints = await read_floats(ctx, probe, "joint-angles")
    answer = await probe.call("solve-forwards", transform=list(pose), current=list(joints))
    ctx.expect_response(answer, clause="solve-forwards.data", expected="six joint angles")
    solved = floats(answer)
    back = await probe.call("solve-backwards", joints=list(solved))
    ctx.expect_response(back, clause="solve-backwards.data", expected="a transform")
    again = floats(back)
    err = max(abs(x - y) for x, y in zip(again, pose, strict=True))
    rotation = max((abs(x - y) for x, y in zip(again[:9], pose[:9], strict=True)), default=0.0)
    position = max((abs(x - y) for x, y in zip(again[9:], pose[9:], strict=True)), default=0.0)
    ctx.expect(
        err < length(ctx, POSITION_TOL_MM),
        clause="solve-forwards.data",
        expected=f"the solved angles reaching the transform (every float within {POSITION_TOL_MM:g})",
        seen=f"position off by {position:.4f} mm, rotation matrix by {rotation:.4f} (a unitless cosine)",
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
                seen=showing(answer, f"float words {w0:04x} {w1:04x} in {op}"),
            )


def bad_patterns(payload: bytes) -> tuple[list[str], list[str]]:
    """(reserved operands, dirty zeros) among the floats of ``payload``, as hex words."""
    reserved: list[str] = []
    dirty: list[str] = []
    for i in range(0, len(payload) - 3, 4):
        w0, w1 = struct.unpack_from("<HH", payload, i)
        if (w0 >> 7) & 0xFF == 0 and (w0 or w1):
            (reserved if w0 & 0x8000 else dirty).append(f"{w0:04x} {w1:04x} at byte {i}")
    return reserved, dirty


@case(
    "server.float.extremes",
    clauses=["float.range", "float.dirty-zero", "float.not-finite", "solve-backwards.data"],
)
async def extremes(ctx: CaseContext) -> None:
    """Solve backwards and forwards driven to the ends of the F range: angles whose sines underflow, angles
    near 1.7e38, transforms out at 1e38 mm.  Every float answered is a representable F value (below
    2^-128 a clean zero, never exponent 0 with fraction bits; never the reserved operand, which is what a
    NaN or an infinity becomes), and a transform answered is a rotation and a position within reach."""
    probe = await ctx.connect()
    joints = await read_floats(ctx, probe, "joint-angles")
    asks: list[tuple[str, dict[str, list[float]]]] = [
        ("solve-backwards", {"joints": list(TINY_WRIST)}),
        ("solve-backwards", {"joints": [TINY] * 6}),
        ("solve-backwards", {"joints": [HUGE, -HUGE, 1e20, 3e37, -HUGE, TINY]}),
    ]
    for position in ([HUGE, HUGE, HUGE], [-HUGE, 0.0, TINY], [TINY, TINY, TINY]):
        transform = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, *position]
        asks.append(("solve-forwards", {"transform": transform, "current": list(joints)}))
    for op, values in asks:
        answer = await probe.call(op, **values)  # type: ignore[arg-type]
        what = f"{op} of {values}"
        if op == "solve-forwards" and answer.opcode == ServerOp.NON_FATAL_ERROR:
            continue  # out of reach: refusing is the answer
        clause = "solve-backwards.data" if op == "solve-backwards" else "float.not-finite"
        ctx.expect_response(answer, clause=clause, expected=f"an answer or a refusal for {what}")
        reserved, dirty = bad_patterns(answer.payload)
        ctx.exercised("float.range")  # every float of the answer read as an F value
        ctx.expect(
            not reserved,
            clause="float.not-finite",
            expected=f"finite floats only in the answer to {what}: never the reserved operand (sign 1, "
            "exponent 0), which is what a NaN or an infinity becomes",
            seen=showing(answer, "; ".join(reserved)),
        )
        ctx.expect(
            not dirty,
            clause="float.dirty-zero",
            expected=f"floats below 2^-128 in the answer to {what} sent as a clean zero (erratum "
            "float-decode)",
            seen=showing(answer, "exponent 0 with fraction bits: " + "; ".join(dirty)),
        )
        if op != "solve-backwards" or reserved:
            continue
        pose = floats(answer)
        worst = max((abs(v) for v in pose[:9]), default=0.0)
        ctx.expect(
            len(pose) == 12 and worst <= 1.0 + ORTHO_TOL and math.hypot(*pose[9:]) <= length(ctx, REACH_MM),
            clause="solve-backwards.data",
            expected=f"a rotation and a position within {length(ctx, REACH_MM):g} {ctx.options.length_unit} "
            f"for {what}",
            seen=str([f"{v:.4g}" for v in pose]),
        )
    await _underflow_flushed(ctx, probe)


def unflushed(zero: Sequence[float], tiny: Sequence[float]) -> list[str]:
    """The rotation entries of ``tiny`` (solve backwards of :data:`TINY_WRIST`) that are not zero where
    those of ``zero`` (of every joint at 0) are, each as its value and its place."""
    pairs = zip(zero[:9], tiny[:9], strict=True)
    return [f"{v:.4g} at float {i + 1}" for i, (z, v) in enumerate(pairs) if z == 0.0 and v != 0.0]


async def _underflow_flushed(ctx: CaseContext, probe: Probe) -> None:
    """float.range: a rotation entry that is zero with every joint at 0 is zero with the wrist joints at
    :data:`TINY` degrees, whose change to it (at most 3 sin(TINY degrees), about 5e-40) is below 2^-128:
    sent as zero, never as the smallest F magnitude or another value F cannot give it."""
    zero = await probe.call("solve-backwards", joints=[0.0] * 6)
    tiny = await probe.call("solve-backwards", joints=list(TINY_WRIST))
    if not (zero.is_response and tiny.is_response):
        return  # a refusal: the answers above judged it
    wrong = unflushed(floats(zero), floats(tiny))
    wanted = (
        f"zero where the rotation of all joints at 0 has zero, for joints {list(TINY_WRIST)}: a magnitude "
    )
    wanted += "below 2^-128 is sent as zero"
    ctx.expect(not wrong, clause="float.range", expected=wanted, seen=showing(tiny, "; ".join(wrong)))
