"""ADC8 (the 1985 guide, B.4) and the strain-gauge wrist it reads (docs/kinematics.md §5).

The filter
----------
Each of the eight channels is smoothed with Y_k = (u_k + u_{k-1} + 6·Y_{k-1}) / 8 using only shifts and
adds, as the 1985 guide says: ``s = u_k + u_{k-1} + (Y << 2) + (Y << 1)`` then ``Y_k = s >> 3``, an arithmetic
shift right (the PDP-11's ASR/ASH), which rounds toward minus infinity (errata ``cougar-filter-rounding``).
No rounding constant is added and no fraction bits are kept between ticks.

Consequences, all measured from this integer code by the tests:

* Frequency response: H(z) = (1 + z⁻¹) / (8 − 6z⁻¹); unity DC gain, a zero at Nyquist, and the −3 dB
  point at fs·acos(0.96)/2π: 2.710 Hz at 60 Hz ticks and 2.823 Hz at 62.5 Hz (the 1985 guide's "2.8 Hz").
* DC behaviour: for a constant input u the output settles inside [u − 3, u].  Coming down onto u it
  settles exactly on u (while Y > u the error shrinks by a quarter, rounded down, until it is 0); coming up
  onto u it stops short, 1 to 3 counts low, because floor(0.75·d) = d for d = −1, −2, −3.  A steady
  reading can therefore be up to 3 counts (0.75 oz with the default gains) low, depending on history;
  noise of a count or more dithers it to an average bias of about −1.5 counts.
* Cougar subtracts the gauge offset vector from each sample before the filter, "prior to any other
  processing" (§8.3).  While the offsets stay constant that is bit-identical to subtracting them after
  the filter (the coefficients sum to 8, and floor(x/8 − c) = floor(x/8) − c); a WGOV mid-run differs:
  the step in the offsets passes through the filter like any other step of the input, so forces move to
  their new value over a few ticks instead of jumping (erratum ``cougar-filter-rounding``).

The wrist
---------
A Maltese-cross sensor: four bars at 0°, 90°, 180°, 270° around a hub of radius r, each with a tangential
and an out-of-plane half bridge, gauges ordered (t1, z1, t2, z2, t3, z3, t4, z4).  Equilibrium gives the
wrench from the bar loads, W = E·loads; equal bars share a load by minimum norm, so the gauges read
w = k·E⁺·W (+ cross-coupling, offsets and noise), rounded to the nearest count and saturated to 12 bits.
Forces are in ounces, torques in ounce-inches (the 1985 guide's LIMIT units), r in inches.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Final

import numpy as np
import numpy.typing as npt

__all__ = [
    "ADC_MAX",
    "ADC_MIN",
    "GAUGES",
    "GaugeModel",
    "adc8_filter",
    "resolution_pattern",
]

GAUGES: Final = 8
ADC_MIN: Final = -2048
ADC_MAX: Final = 2047
#: Volts per count: the ±10 V wrist range over 2048 counts (§8.2).
VOLTS_PER_COUNT: Final = 10.0 / 2048.0

FloatArray = npt.NDArray[np.float64]


def adc8_filter(u: int, u_previous: int, y_previous: int) -> int:
    """One ADC8 filter step on integers: (u_k + u_{k-1} + 6·Y_{k-1}) / 8 by shifts and adds (ASR rounding)."""
    s = u + u_previous + (y_previous << 2) + (y_previous << 1)
    return s >> 3


def resolution_pattern(r: float) -> FloatArray:
    """E (6x8): the wrench (Fx, Fy, Fz, Mx, My, Mz) from the bar loads (t1, z1, ..., t4, z4)."""
    return np.array(
        [
            [0, 0, -1, 0, 0, 0, 1, 0],
            [1, 0, 0, 0, -1, 0, 0, 0],
            [0, 1, 0, 1, 0, 1, 0, 1],
            [0, 0, 0, r, 0, 0, 0, -r],
            [0, -r, 0, 0, 0, r, 0, 0],
            [r, 0, r, 0, r, 0, r, 0],
        ],
        dtype=np.float64,
    )


@dataclass(frozen=True)
class GaugeModel:
    """The physical wrist: how a wrench on the hand becomes eight gauge counts.

    ``counts_per_oz``: gauge counts per ounce of bar load; the defaults put ±512 oz of force and ±512 oz-in
    of torque inside the converter's range with 0.25 oz per count (the 1985 guide's wrist resolved about
    0.5 oz).
    ``cross_coupling``: relative size of a fixed random 6x6 coupling (drawn from ``coupling_seed``), as a
    real sensor has a few percent.  ``offsets``: the gauge offsets (counts) read with no load.
    ``noise``: standard deviation of the per-sample noise (counts), drawn from the simulator's seed.
    """

    hub_radius_in: float = 1.0
    counts_per_oz: float = 8.0
    cross_coupling: float = 0.0
    coupling_seed: int = 1985
    offsets: tuple[int, ...] = (0,) * GAUGES
    noise: float = 0.0
    _c: FloatArray = field(init=False, repr=False, compare=False)
    _offsets: FloatArray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if len(self.offsets) != GAUGES:
            raise ValueError(f"GaugeModel.offsets needs {GAUGES} values, got {len(self.offsets)}")
        if self.hub_radius_in <= 0 or self.counts_per_oz <= 0 or self.noise < 0:
            raise ValueError("GaugeModel needs hub_radius_in > 0, counts_per_oz > 0 and noise >= 0")
        c = self.counts_per_oz * np.linalg.pinv(resolution_pattern(self.hub_radius_in))
        if self.cross_coupling:
            n = np.random.default_rng(self.coupling_seed).standard_normal((6, 6))
            c = c @ (np.eye(6) + self.cross_coupling * n)
        c.setflags(write=False)
        object.__setattr__(self, "_c", c)
        offsets = np.asarray(self.offsets, dtype=np.float64)
        offsets.setflags(write=False)
        object.__setattr__(self, "_offsets", offsets)

    @property
    def sensitivity(self) -> FloatArray:
        """C (8x6): gauge counts per unit of wrench (oz, oz-in) at the wrist centre, hand coordinates."""
        return self._c

    def calibration_matrix(self) -> FloatArray:
        """The calibration matrix (6x8, oz per volt) an exact calibration of this wrist would give."""
        cal: FloatArray = np.asarray(np.linalg.pinv(self._c) / VOLTS_PER_COUNT, dtype=np.float64)
        return cal

    def analog(self, wrench: FloatArray, rng: np.random.Generator | None = None) -> FloatArray:
        """Gauge outputs in counts before conversion: C·W + offsets (+ noise)."""
        w = self._c @ wrench + self._offsets
        if self.noise and rng is not None:
            w = w + rng.normal(0.0, self.noise, GAUGES)
        return w

    def convert(self, analog: FloatArray) -> list[int]:
        """The A/D conversion: nearest count (ties to even), saturated to −2048..2047; NaN reads 0."""
        # Python's round() of a float is numpy's rint (half-even), and clipping before or after rounding
        # gives the same count for anything outside the range, infinities included.
        return [
            ADC_MAX if v > ADC_MAX else ADC_MIN if v < ADC_MIN else 0 if math.isnan(v) else round(v)
            for v in np.asarray(analog, dtype=np.float64).tolist()
        ]
