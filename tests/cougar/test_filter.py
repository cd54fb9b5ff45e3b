"""ADC8's integer filter (the 1985 guide, B.4) and the output FILTER (B.10), measured from the
implementations."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from manip.cougar.adc import adc8_filter
from manip.cougar.compliance import filter_constants, output_filter

gauge = st.integers(-2048, 2047)


def run(samples: list[int], y0: int = 0, u0: int = 0) -> list[int]:
    out, u_prev, y = [], u0, y0
    for u in samples:
        y = adc8_filter(u, u_prev, y)
        u_prev = u
        out.append(y)
    return out


def gain_at(freq: float, fs: float, amplitude: float = 1500.0) -> float:
    """|H| at ``freq`` from the integer filter: least-squares sine fits of the rounded input and output."""
    n, skip = 3000, 300
    k = np.arange(n)
    u = [int(v) for v in np.rint(amplitude * np.sin(2 * math.pi * freq * k / fs))]
    y = np.array(run(u), dtype=np.float64)
    basis = np.column_stack(
        [np.sin(2 * math.pi * freq * k / fs), np.cos(2 * math.pi * freq * k / fs), np.ones(n)]
    )[skip:]
    cy = np.linalg.lstsq(basis, y[skip:], rcond=None)[0]
    cu = np.linalg.lstsq(basis, np.array(u, dtype=np.float64)[skip:], rcond=None)[0]
    return float(math.hypot(cy[0], cy[1]) / math.hypot(cu[0], cu[1]))


def minus_3db(fs: float) -> float:
    lo, hi = 1.0, 6.0
    for _ in range(30):
        mid = (lo + hi) / 2
        if gain_at(mid, fs) > 1 / math.sqrt(2):
            lo = mid
        else:
            hi = mid
    return (lo + hi) / 2


def test_step_weights_are_the_guides_formula() -> None:
    # Step of 800 from rest: 800*(1/8, 11/32, ...) rounded down at each step by the ASR.
    out = run([800] * 4)
    assert out[0] == (800 + 0 + 0) >> 3 == 100
    assert out[1] == (800 + 800 + 6 * 100) >> 3 == 275
    assert out[2] == (1600 + 6 * 275) // 8


def test_asr_rounds_toward_minus_infinity() -> None:
    assert adc8_filter(-1, 0, 0) == -1  # -1/8 rounds down, not to zero
    assert adc8_filter(1, 0, 0) == 0
    assert adc8_filter(7, 0, 0) == 0


@pytest.mark.parametrize("amplitude", [1000, -1000, 2047, -2048, 3])
def test_unity_dc_gain_from_above_and_below(amplitude: int) -> None:
    # Coming down onto the value the filter lands exactly on it; coming up it stops 1..3 counts short.
    from_below = run([amplitude] * 200, y0=amplitude - 500, u0=amplitude)[-1]
    from_above = run([amplitude] * 200, y0=amplitude + 500, u0=amplitude)[-1]
    assert from_above == amplitude
    assert amplitude - 3 <= from_below < amplitude
    assert from_below / amplitude == pytest.approx(1.0, abs=3 / abs(amplitude) + 1e-12)


@given(u=gauge, y=st.integers(-2048, 2047))
def test_constant_input_settles_within_three_counts_below(u: int, y: int) -> None:
    final = run([u] * 60, y0=y, u0=u)[-1]
    assert u - 3 <= final <= u
    if y >= u:
        assert final == u


@given(samples=st.lists(gauge, min_size=1, max_size=50), offset=st.integers(-2048, 2047))
def test_offset_before_or_after_the_filter_is_bit_identical(samples: list[int], offset: int) -> None:
    before = run([s - offset for s in samples], y0=-offset, u0=-offset)
    after = [y - offset for y in run(samples)]
    assert before == after


def test_zero_at_nyquist() -> None:
    out = run([1000, -1000] * 50)
    assert all(abs(y) <= 1 for y in out[-20:])


@pytest.mark.parametrize(("fs", "expected"), [(60.0, 2.7100), (62.5, 2.8230)])
def test_minus_3db_point_measured_from_the_integer_filter(fs: float, expected: float) -> None:
    f3 = minus_3db(fs)
    assert f3 == pytest.approx(expected, abs=0.01)
    # and it agrees with the closed form fs*acos(0.96)/2pi (docs/kinematics.md §5.2)
    assert f3 == pytest.approx(fs * math.acos(0.96) / (2 * math.pi), abs=0.01)


def test_gain_follows_the_transfer_function() -> None:
    for f in (0.5, 2.0, 5.0, 10.0, 20.0):
        w = 2 * math.pi * f / 60.0
        h = abs((1 + np.exp(-1j * w)) / (8 - 6 * np.exp(-1j * w)))
        assert gain_at(f, 60.0) == pytest.approx(h, rel=0.01, abs=2e-3)


# ---------------------------------------------------------------------------------------- B.10 FILTER
def test_filter_constants_are_the_guides() -> None:
    a, t = 2 * math.pi * 2.0, 1 / 60
    con = filter_constants(2.0, 60.0, 0.25, 0.75)
    assert con == pytest.approx((2 / (a * t + 2), (a * t - 2) / (a * t + 2), 0.25, 0.75))


def test_output_filter_passes_through_with_default_constants() -> None:
    con = np.array(filter_constants(2.0, 60.0, 0.0, 1.0))
    prev = filt = np.zeros(6)
    for x in (1.0, -3.0, 7.5):
        sample = np.full(6, x)
        filt, out = output_filter(sample, prev, filt, con)
        prev = sample
        assert np.array_equal(out, sample)


def test_filtered_part_is_a_high_pass() -> None:
    con = np.array(filter_constants(2.0, 60.0, 1.0, 0.0))
    prev = filt = np.zeros(1)
    outs = []
    for _ in range(300):  # a step: the filtered part jumps by con1 then decays to zero
        sample = np.ones(1)
        filt, out = output_filter(sample, prev, filt, con)
        prev = sample
        outs.append(float(out[0]))
    assert outs[0] == pytest.approx(con[0])
    assert abs(outs[-1]) < 1e-6
    assert all(b <= a for a, b in itertools.pairwise(outs))
