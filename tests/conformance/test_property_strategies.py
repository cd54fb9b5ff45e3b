"""The conformance strategies generate what they claim: valid data by the spec layouts, in-range and
out-of-range joint angles, speed factors on the right side of the bound, and malformed variants that
the codec itself rejects for the right reason."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from manip.arm.kinematics import PUMA600
from manip.codecs.errors import DecodeError
from manip.codecs.messages import decode_request
from manip.codecs.pdp11float import f_to_u32, u32_to_f
from manip.conformance.suite.strategies import (
    ALL_HAZARDS,
    F_RELATIVE_ULP,
    SAFE_HAZARDS,
    bad_speed_factors,
    f_floats,
    f_floats_between,
    f_round,
    f_ulp,
    float_requests,
    joints_near,
    joints_out_of_range,
    joints_within,
    requests_of,
    reserved_float_data,
    speed_factors,
    step_from,
    unit_offsets,
    unknown_opcodes,
    valid_requests,
    wrong_length_data,
)
from manip.spec import SPEC

LIMITS = PUMA600.limits
FIXED = [op for op in requests_of(ALL_HAZARDS) if op.request.fixed_size is not None]


def exact(x: float) -> bool:
    return u32_to_f(f_to_u32(x)) == x


@given(f_floats)
def test_f_floats_are_exact_f_values(x: float) -> None:
    assert math.isfinite(x)
    assert exact(x)


def test_f_ulp_is_the_24th_bit() -> None:
    assert f_ulp(1.0) == 2.0**-23  # [1, 2): 24 bits reach 2^-23
    assert f_ulp(0.75) == 2.0**-24
    assert f_ulp(-96.0) == 2.0**-17
    assert f_round(1.0 + f_ulp(1.0)) == 1.0 + f_ulp(1.0)
    assert f_round(1.0 + f_ulp(1.0) / 4) == 1.0
    assert f_ulp(1.0) <= F_RELATIVE_ULP * 1.0


@given(valid_requests(requests_of(ALL_HAZARDS)))
def test_valid_requests_decode_by_their_layout(request: tuple[object, bytes]) -> None:
    op, data = request
    assert decode_request(op.opcode, data).op is op  # type: ignore[attr-defined]


def test_requests_of_respects_hazards() -> None:
    safe = requests_of(SAFE_HAZARDS)
    assert safe and all(op.hazard in SAFE_HAZARDS for op in safe)
    assert {op.name for op in requests_of(ALL_HAZARDS)} == {op.name for op in SPEC.requests.values()}
    assert "free-joint" not in {op.name for op in requests_of(SAFE_HAZARDS, exclude=["here"])}
    assert "here" not in {op.name for op in requests_of(SAFE_HAZARDS, exclude=["here"])}


@given(joints_within(LIMITS, margin=0.5))
def test_joints_within_are_in_range(q: tuple[float, ...]) -> None:
    assert LIMITS.violations(q, tol=-0.5 + 1e-9) == []
    assert all(exact(v) for v in q)


@given(joints_out_of_range(LIMITS))
def test_joints_out_of_range_name_the_offending_joints(
    case: tuple[tuple[float, ...], tuple[int, ...]],
) -> None:
    q, bad = case
    assert LIMITS.violations(q) == list(bad)
    assert all(exact(v) for v in q)


@given(st.data())
def test_joints_near_stay_near_and_in_range(data: st.DataObject) -> None:
    start = data.draw(joints_within(LIMITS, margin=0.0))
    goal = data.draw(joints_near(start, LIMITS, step=2.0))
    assert all(abs(g - s) <= 2.0 + 1e-4 for g, s in zip(goal, start, strict=True))
    assert LIMITS.violations(goal) == []


@given(unit_offsets, joints_within(LIMITS, margin=0.0))
def test_step_from_is_in_range_and_exact(offsets: tuple[float, ...], start: tuple[float, ...]) -> None:
    goal = step_from(start, offsets, LIMITS, step=5.0)
    assert LIMITS.violations(goal) == []
    assert all(exact(v) for v in goal)
    assert all(abs(g - s) <= 5.0 + 1e-3 for g, s in zip(goal, start, strict=True))


@given(speed_factors)
def test_speed_factors_are_allowed(f: float) -> None:
    assert 0.0 < f <= 1.0 and exact(f)


@given(bad_speed_factors)
def test_bad_speed_factors_are_not(f: float) -> None:
    assert not 0.0 < f <= 1.0
    assert exact(f)


@given(unknown_opcodes())
def test_unknown_opcodes_are_request_range_and_unassigned(opcode: int) -> None:
    assert 0o200 <= opcode <= 0o277
    assert opcode not in SPEC.requests


@pytest.mark.parametrize("op", FIXED, ids=lambda op: op.name)
@settings(max_examples=8)
@given(data=st.data())
def test_wrong_length_data_is_rejected_as_a_length_error(op: object, data: st.DataObject) -> None:
    body = data.draw(wrong_length_data(op))  # type: ignore[arg-type]
    with pytest.raises(DecodeError) as info:
        decode_request(op.opcode, body)  # type: ignore[attr-defined]
    assert info.value.clause == "request.data-length"


@pytest.mark.parametrize("op", float_requests(), ids=lambda op: op.name)
@settings(max_examples=8)
@given(data=st.data())
def test_reserved_float_data_is_rejected_at_its_offset(op: object, data: st.DataObject) -> None:
    body, offset = data.draw(reserved_float_data(op))  # type: ignore[arg-type]
    with pytest.raises(DecodeError) as info:
        decode_request(op.opcode, body)  # type: ignore[attr-defined]
    assert info.value.clause == "float.reserved-operand"
    assert info.value.offset == offset


def test_f_floats_between_bounds() -> None:
    with pytest.raises(ValueError):
        f_floats_between(2.0, 1.0)

    @given(f_floats_between(-0.05, 0.05))
    def inner(x: float) -> None:
        assert -0.05 <= x <= 0.05 and exact(x)

    inner()
