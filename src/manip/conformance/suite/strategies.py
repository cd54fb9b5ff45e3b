"""Hypothesis strategies for the conformance cases, derived from the spec tables.

Nothing here names an opcode's layout: request data are generated field by field from the layouts in
``manip/spec/data/manip.toml`` and encoded with :func:`manip.codecs.messages.encode_request`; joint angles
respect the joint limits of :mod:`manip.arm.kinematics` (or the limits a server states in its
describe-self reply); every float is a value a PDP-11 F float can carry exactly, so what is sent is
exactly what was generated.

Three families:

* **valid**: :func:`request_data` / :func:`valid_requests` (any request of the allowed hazard classes with
  data of the right layout), :func:`joints_within`, :func:`joints_near` (goals a few degrees from where
  the arm is, so moves end quickly), :data:`speed_factors`;
* **refused by the spec**: :func:`joints_out_of_range` (JOR), :data:`bad_speed_factors` (C), masks with
  undefined bits;
* **malformed**: :func:`unknown_opcodes`, :func:`wrong_length_data`, :func:`reserved_float_data`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any, Final

from hypothesis import strategies as st

from manip.arm.kinematics import PUMA600, JointLimits, Joints
from manip.codecs.messages import encode_request
from manip.codecs.pdp11float import F_MAX, f_to_u32, u32_to_f
from manip.spec import SPEC, FieldType, Layout, RequestOpcode
from manip.spec.model import HAZARDS, Hazard

__all__ = [
    "ALL_HAZARDS",
    "F_RELATIVE_ULP",
    "SAFE_HAZARDS",
    "bad_speed_factors",
    "f_floats",
    "f_floats_between",
    "f_round",
    "f_ulp",
    "field_values",
    "float_requests",
    "joints_near",
    "joints_out_of_range",
    "joints_within",
    "layout_values",
    "request_data",
    "requests_of",
    "reserved_float_data",
    "speed_factors",
    "step_from",
    "unit_offsets",
    "unknown_opcodes",
    "valid_requests",
    "wrong_length_data",
]

#: A PDP-11 F float has a 24-bit significand (23 stored bits and a hidden one): one unit in the last
#: place is 2^-23 of the value's binade floor, so relative to the value it is at most 2^-23.
F_RELATIVE_ULP: Final = 2.0**-23
#: Hazard classes safe on real hardware: nothing moves and power is not touched.
SAFE_HAZARDS: Final[frozenset[Hazard]] = frozenset({"read-only", "config"})
ALL_HAZARDS: Final[frozenset[Hazard]] = frozenset(HAZARDS)
#: Request opcodes are 0200-0277 (clause request.opcode-range).
REQUEST_OPCODES: Final = range(0o200, 0o300)
MAX_DATA: Final = 488


# ------------------------------------------------------------------------------------------ floats
def f_round(x: float) -> float:
    """``x`` rounded to the nearest PDP-11 F value (half to even; underflow to zero)."""
    return u32_to_f(f_to_u32(float(x)))


def f_ulp(x: float) -> float:
    """One unit in the last (24th) significand bit of the F value ``x`` (of the smallest normal at 0)."""
    if x == 0.0:
        return math.ldexp(1.0, -128 - 23)
    _, exp = math.frexp(x)  # |x| = m * 2^exp with 0.5 <= m < 1: 24 bits reach down to 2^(exp-24)
    return math.ldexp(1.0, exp - 24)


def _not_reserved(u: int) -> bool:
    return not (u & 0x8000 and (u >> 7) & 0xFF == 0)


def _clean_zero(u: int) -> int:
    """Dirty zeros (exponent 0, fraction bits set) are sent as a clean zero (clause float.dirty-zero)."""
    return u if (u >> 7) & 0xFF else 0


#: Every F value, drawn by bit pattern so the exponent extremes (1 and 255) come up as often as 1.0.
f_floats: Final = st.integers(0, 2**32 - 1).filter(_not_reserved).map(_clean_zero).map(u32_to_f)


def f_floats_between(lo: float, hi: float) -> st.SearchStrategy[float]:
    """F values in ``[lo, hi]`` (both ends included when representable)."""
    if not lo <= hi:
        raise ValueError(f"empty range [{lo}, {hi}]")
    return (
        st.floats(lo, hi, allow_nan=False, allow_infinity=False).map(f_round).filter(lambda x: lo <= x <= hi)
    )


# ------------------------------------------------------------------------------ values by layout
def _element(element: str) -> st.SearchStrategy[Any]:
    match element:
        case "float":
            return f_floats
        case "word":
            return st.integers(0, 0xFFFF)
        case "int16":
            return st.integers(-0x8000, 0x7FFF)
        case "small":
            return st.integers(0, 0xFF)
    raise ValueError(f"no strategy for element {element!r}")


def field_values(ft: FieldType) -> st.SearchStrategy[Any]:
    """Values of one field type, in the form :func:`encode_request` takes."""
    if ft.element == "counted":
        return st.lists(st.integers(0, 0xFFFF), max_size=64).map(tuple)
    if ft.element == "text":
        return st.text(st.characters(min_codepoint=0x20, max_codepoint=0x7E), min_size=1, max_size=200)
    one = _element(ft.element)
    count = ft.count or 1
    if count == 1:
        return one
    return st.lists(one, min_size=count, max_size=count).map(tuple)


def layout_values(layout: Layout) -> st.SearchStrategy[dict[str, Any]]:
    return st.fixed_dictionaries({f.name: field_values(f.type) for f in layout.fields})


def request_data(op: RequestOpcode) -> st.SearchStrategy[bytes]:
    """Data bytes of a well-formed ``op`` request (any values its layout allows)."""
    return layout_values(op.request).map(lambda values: encode_request(op.opcode, **values))


def requests_of(hazards: Iterable[Hazard], *, exclude: Iterable[str] = ()) -> list[RequestOpcode]:
    """The spec's requests of the given hazard classes, by opcode, minus the names in ``exclude``."""
    allowed, skip = frozenset(hazards), frozenset(exclude)
    return [
        op
        for op in sorted(SPEC.requests.values(), key=lambda r: r.opcode)
        if op.hazard in allowed and op.name not in skip
    ]


def valid_requests(ops: Sequence[RequestOpcode]) -> st.SearchStrategy[tuple[RequestOpcode, bytes]]:
    """One of ``ops`` with well-formed data."""
    if not ops:
        raise ValueError("no request opcodes to draw from")
    return st.sampled_from(list(ops)).flatmap(lambda op: st.tuples(st.just(op), request_data(op)))


# --------------------------------------------------------------------------------- joint angles
def _six(values: Sequence[float]) -> Joints:
    return (values[0], values[1], values[2], values[3], values[4], values[5])


def joints_within(limits: JointLimits = PUMA600.limits, margin: float = 0.5) -> st.SearchStrategy[Joints]:
    """F-representable joint angles at least ``margin`` degrees inside every limit."""
    per_joint = [
        f_floats_between(lo + margin, hi - margin) for lo, hi in zip(limits.lower, limits.upper, strict=True)
    ]
    return st.tuples(*per_joint).map(_six)


def joints_near(
    start: Sequence[float], limits: JointLimits = PUMA600.limits, step: float = 5.0, margin: float = 0.01
) -> st.SearchStrategy[Joints]:
    """F-representable goals within ``step`` degrees of ``start`` on each joint, inside the limits.

    Small steps keep moves short (a few hundred milliseconds on the reference arm), so a run can wait for
    them; every significand bit still varies.
    """
    per_joint = []
    for q, lo, hi in zip(start, limits.lower, limits.upper, strict=True):
        a, b = max(lo + margin, q - step), min(hi - margin, q + step)
        if a > b:  # the start itself is outside the limits: aim at the nearest in-range angle
            a = b = min(max(q, lo + margin), hi - margin)
        per_joint.append(f_floats_between(a, b))
    return st.tuples(*per_joint).map(_six)


#: Six offsets in [-1, 1], to be scaled by :func:`step_from`.  The stateful machine draws these rather
#: than :func:`joints_near` of the arm's current position: a draw's bounds must not depend on the
#: target's state, or Hypothesis sees a different strategy on replay (FlakyStrategyDefinition).
unit_offsets: Final = st.tuples(*[st.floats(-1.0, 1.0, allow_nan=False)] * 6)


def step_from(
    start: Sequence[float],
    offsets: Sequence[float],
    limits: JointLimits = PUMA600.limits,
    step: float = 5.0,
    margin: float = 0.01,
) -> Joints:
    """``start`` moved by ``step * offsets`` degrees, kept ``margin`` inside the limits, in F precision."""
    out = [
        f_round(min(max(q + step * u, lo + margin), hi - margin))
        for q, u, lo, hi in zip(start, offsets, limits.lower, limits.upper, strict=True)
    ]
    return _six(out)


@st.composite
def joints_out_of_range(
    draw: st.DrawFn, limits: JointLimits = PUMA600.limits, start: Sequence[float] | None = None
) -> tuple[Joints, tuple[int, ...]]:
    """Joint angles with at least one joint at least 1 degree past a limit, and the offending joints.

    The other joints are in range (near ``start`` when given), so only the limits can explain a refusal.
    """
    base = list(draw(joints_near(start, limits) if start is not None else joints_within(limits)))
    bad = draw(st.lists(st.integers(1, 6), min_size=1, max_size=3, unique=True))
    for j in bad:
        lo, hi = limits.lower[j - 1], limits.upper[j - 1]
        over = draw(st.floats(1.0, 720.0))
        base[j - 1] = f_round(hi + over) if draw(st.booleans()) else f_round(lo - over)
    return _six(base), tuple(sorted(bad))


# ------------------------------------------------------------------------------------ speed factors
#: Speed factors the spec allows: 0 < n <= 1 (clause speed.range), with 1 and tiny factors favoured.
speed_factors: Final = st.one_of(
    st.just(1.0), st.just(u32_to_f(0x80)), f_floats_between(1e-6, 1.0).filter(lambda x: x > 0.0)
)
#: Speed factors the spec refuses: zero, negatives, anything above 1 (the next F value after 1 included).
bad_speed_factors: Final = st.one_of(
    st.just(0.0),
    st.just(1.0 + F_RELATIVE_ULP),
    f_floats.filter(lambda x: x <= 0.0 or x > 1.0),
    st.sampled_from([-1.0, 2.0, F_MAX, -F_MAX]),
)


# ---------------------------------------------------------------------------------- malformed data
def unknown_opcodes() -> st.SearchStrategy[int]:
    """Request-range opcodes (0200-0277) the spec does not define."""
    return st.sampled_from([op for op in REQUEST_OPCODES if op not in SPEC.requests])


def _accepted_sizes(op: RequestOpcode) -> frozenset[int]:
    size = op.request.fixed_size
    if size is None:
        return frozenset()
    small = any(f.type.element == "small" for f in op.request.fields)
    return frozenset({size, size - 1} if small else {size})


@st.composite
def wrong_length_data(draw: st.DrawFn, op: RequestOpcode) -> bytes:
    """Data whose length fits no layout of ``op`` (clause request.data-length): a valid body cut short
    or extended, or arbitrary bytes of another length (at most 488)."""
    accepted = _accepted_sizes(op)
    if not accepted:
        raise ValueError(f"{op.name} has no fixed size")
    body = draw(request_data(op))
    length = draw(
        st.one_of(
            st.integers(0, max(accepted) + 8),
            st.integers(0, MAX_DATA),
        ).filter(lambda n: n not in accepted)
    )
    if length <= len(body):
        return body[:length]
    return body + draw(st.binary(min_size=length - len(body), max_size=length - len(body)))


def _float_offsets(layout: Layout) -> list[int]:
    offsets: list[int] = []
    at = 0
    for f in layout.fields:
        size = f.type.fixed_size
        if size is None:
            break
        if f.type.element == "float":
            offsets.extend(at + 4 * i for i in range(f.type.count or 0))
        at += size
    return offsets


@st.composite
def reserved_float_data(draw: st.DrawFn, op: RequestOpcode) -> tuple[bytes, int]:
    """Well-formed ``op`` data with one float replaced by a reserved operand (sign 1, exponent 0), and
    the byte offset of that float (clause request.reserved-float)."""
    offsets = _float_offsets(op.request)
    if not offsets:
        raise ValueError(f"{op.name} carries no float")
    body = bytearray(draw(request_data(op)))
    at = draw(st.sampled_from(offsets))
    fraction = draw(st.integers(0, 2**23 - 1))
    u = 0x8000 | (fraction >> 16) | (fraction & 0xFFFF) << 16  # exponent bits 7-14 of word 0 are zero
    body[at : at + 4] = u.to_bytes(4, "little")
    return bytes(body), at


def float_requests() -> list[RequestOpcode]:
    """Requests whose layout carries at least one float."""
    return [op for op in requests_of(ALL_HAZARDS) if _float_offsets(op.request)]
